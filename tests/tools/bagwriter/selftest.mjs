#!/usr/bin/env node
// Writes every variant of a bag from one sequence with write_bag.mjs, reads
// each back with read_bag.mjs and checks it against the sequence files.
//   node selftest.mjs --sequence DIR [--last 20] [--workdir DIR]
// Ends with the line "N passed, M failed"; exit code 1 if anything failed.
import fs from "node:fs";
import os from "node:os";
import path from "node:path";
import { spawnSync } from "node:child_process";
import { fileURLToPath } from "node:url";
import { openSequence, stampNs } from "./lib/sequence.mjs";

const here = path.dirname(fileURLToPath(import.meta.url));
const args = process.argv.slice(2);
const opt = (name, dflt) => {
  const i = args.indexOf(name);
  return i >= 0 ? args[i + 1] : dflt;
};
const sequence = opt("--sequence");
const last = Number(opt("--last", "20"));
if (!sequence) {
  console.error("usage: node selftest.mjs --sequence DIR [--last 20] [--workdir DIR]");
  process.exit(1);
}
const work = opt("--workdir") ?? fs.mkdtempSync(path.join(os.tmpdir(), "bagwriter-selftest-"));
fs.mkdirSync(work, { recursive: true });

let passed = 0;
let failed = 0;
function check(name, ok, detail = "") {
  if (ok) passed++;
  else failed++;
  console.log(`${ok ? "ok  " : "FAIL"} ${name}${detail ? ": " + detail : ""}`);
}
const hasTool = (t) => spawnSync("sh", ["-c", `command -v ${t}`]).status === 0;
const node = (script, a) => spawnSync(process.execPath, [path.join(here, script), ...a], { encoding: "utf8", maxBuffer: 1 << 26 });

// what the bag must contain
const seq = openSequence(sequence);
const sel = seq.scanPaths.map((_, i) => i).slice(-last);
const i0 = sel[0];
const scan0 = seq.readScan(i0);
const f32 = (x) => Math.fround(x);
const stamp0 = seq.stamps[i0];
const pose0 = seq.poses[i0];
const N = sel.length;

const LAYOUT = {
  xyzi: [["x", 0, 7], ["y", 4, 7], ["z", 8, 7], ["intensity", 12, 7]],
  ixyz: [["intensity", 0, 7], ["x", 4, 7], ["y", 8, 7], ["z", 12, 7]],
  xyz_ring_i_f64: [["x", 0, 8], ["y", 8, 8], ["z", 16, 8], ["ring", 24, 4], ["intensity", 28, 7]],
};
const MAGIC = { zstd: "28b52ffd", lz4: "04224d18" };

function rotationFromQuat({ x, y, z, w }) {
  return [
    1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w),
    2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w),
    2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y),
  ];
}

function checkContent(tag, r, { fieldOrder = "xyzi", tf = false }) {
  const counts = Object.fromEntries(r.topics.map((t) => [t.topic, t.count]));
  const want = { "/points": N, "/odom": N, ...(tf ? { "/tf": N, "/tf_static": 1 } : {}) };
  check(`${tag}: message counts`, JSON.stringify(Object.entries(counts).sort()) === JSON.stringify(Object.entries(want).sort()), JSON.stringify(counts));
  const c = r.first_cloud;
  if (!c) return check(`${tag}: has a PointCloud2`, false);
  const fields = c.fields.map((f) => [f.name, f.offset, f.datatype]);
  check(`${tag}: fields ${fieldOrder}`, JSON.stringify(fields) === JSON.stringify(LAYOUT[fieldOrder]), JSON.stringify(fields));
  check(`${tag}: width/height/step`, c.width === scan0.n && c.height === 1 && c.row_step === c.point_step * c.width && c.data_bytes === c.row_step && !c.is_bigendian && c.is_dense,
    `width ${c.width} (scan has ${scan0.n}), point_step ${c.point_step}`);
  const [x, y, z, i] = scan0.xyzi.slice(0, 4);
  const p = c.first_point;
  const exp = fieldOrder === "xyz_ring_i_f64" ? { x, y, z, intensity: f32(i) } : { x: f32(x), y: f32(y), z: f32(z), intensity: f32(i) };
  const same = ["x", "y", "z", "intensity"].every((k) => p[k] === exp[k]);
  check(`${tag}: first point equals first point of scan ${path.basename(seq.scanPaths[i0])}`, same, `${JSON.stringify(p)} vs ${JSON.stringify(exp)}`);
  check(`${tag}: stamp and log time`, c.stamp.sec === stamp0.sec && c.stamp.nanosec === stamp0.nanosec && c.log_time === String(stampNs(stamp0)),
    `${c.stamp.sec}.${c.stamp.nanosec} @ ${c.log_time}`);
  const o = r.first_odom;
  const R = rotationFromQuat(o.orientation);
  const Rexp = [pose0[0], pose0[1], pose0[2], pose0[4], pose0[5], pose0[6], pose0[8], pose0[9], pose0[10]];
  const rotErr = Math.max(...R.map((v, k) => Math.abs(v - Rexp[k])));
  check(`${tag}: odometry pose = poses.txt`, o.position.x === pose0[3] && o.position.y === pose0[7] && o.position.z === pose0[11] && rotErr < 1e-5 && o.frame_id === "map" && o.child_frame_id === "lidar",
    `rotation max error ${rotErr.toExponential(2)}`);
  if (tf) {
    check(`${tag}: /tf map->lidar, /tf_static lidar->lidar_optical`,
      r.first_tf?.parent === "map" && r.first_tf?.child === "lidar" && r.first_tf_static?.parent === "lidar" && r.first_tf_static?.child === "lidar_optical");
  }
}

const variants = [
  { name: "zstd", a: ["--compression", "zstd"], compression: "zstd" },
  { name: "lz4", a: ["--compression", "lz4"], compression: "lz4" },
  { name: "none", a: ["--compression", "none"], compression: "" },
  { name: "unchunked", a: ["--unchunked"], unchunked: true },
  { name: "ixyz", a: ["--field-order", "ixyz"], compression: "zstd", fieldOrder: "ixyz" },
  { name: "f64", a: ["--field-order", "xyz_ring_i_f64"], compression: "zstd", fieldOrder: "xyz_ring_i_f64" },
  { name: "f64-lz4", a: ["--field-order", "xyz_ring_i_f64", "--compression", "lz4"], compression: "lz4", fieldOrder: "xyz_ring_i_f64" },
  { name: "tf", a: ["--tf"], compression: "zstd", tf: true },
  { name: "smallchunks-lz4", a: ["--compression", "lz4", "--chunk-size", "65536", "--tf"], compression: "lz4", tf: true, manyChunks: true },
];

const sizes = [];
for (const v of variants) {
  const out = path.join(work, `${v.name}.mcap`);
  const w = node("write_bag.mjs", ["--sequence", sequence, "--out", out, "--last", String(last), ...v.a]);
  check(`${v.name}: write_bag exit 0`, w.status === 0, (w.stdout + w.stderr).trim());
  if (w.status !== 0) continue;
  sizes.push([path.basename(out), fs.statSync(out).size]);
  const dump = path.join(work, `${v.name}.chunk0`);
  const rd = node("read_bag.mjs", [out, "--json", ...(v.unchunked ? [] : ["--dump-chunk", dump])]);
  check(`${v.name}: read_bag exit 0`, rd.status === 0, rd.stderr.trim());
  if (rd.status !== 0) continue;
  const r = JSON.parse(rd.stdout);
  check(`${v.name}: profile ros2, ros2msg schemas, cdr`, r.profile === "ros2" && r.topics.every((t) => t.schema_encoding === "ros2msg" && t.message_encoding === "cdr"));
  checkContent(v.name, r, v);
  const total = r.topics.reduce((s, t) => s + t.count, 0);
  if (v.unchunked) {
    check(`${v.name}: no chunks, all messages top-level`, r.chunks.length === 0 && r.messages_outside_chunks === total,
      `${r.chunks.length} chunks, ${r.messages_outside_chunks} top-level messages`);
  } else {
    const stats = r.statistics_counts;
    check(`${v.name}: statistics and chunk-index counts agree`, JSON.stringify(stats) === JSON.stringify(r.indexed_counts) && Object.values(stats).reduce((a, b) => a + b, 0) === total);
    check(`${v.name}: ${r.chunks.length} chunk(s), all '${v.compression}'`, r.chunks.length > 0 && r.chunks.every((c) => c.compression === v.compression) && (!v.manyChunks || r.chunks.length > 1));
    if (v.compression) {
      check(`${v.name}: every chunk starts with the ${v.compression} frame magic ${MAGIC[v.compression]}`, r.chunks.every((c) => c.magic === MAGIC[v.compression]),
        [...new Set(r.chunks.map((c) => c.magic))].join(","));
      const tool = v.compression;
      if (hasTool(tool)) {
        const d = spawnSync(tool, ["-d", "-c", "-q", dump], { maxBuffer: 1 << 28 });
        check(`${v.name}: '${tool} -d' CLI decodes chunk 0 to ${r.chunks[0].uncompressed_size} bytes`, d.status === 0 && d.stdout.length === r.chunks[0].uncompressed_size,
          `status ${d.status}, ${d.stdout?.length} bytes ${d.stderr}`);
      }
    }
  }
}

// rosbag2 sqlite3
{
  const out = path.join(work, "db3bag");
  fs.rmSync(out, { recursive: true, force: true });
  const w = node("write_bag.mjs", ["--sequence", sequence, "--out", out, "--last", String(last), "--format", "db3", "--tf"]);
  check("db3: write_bag exit 0", w.status === 0, (w.stdout + w.stderr).trim());
  const dbFile = path.join(out, "db3bag_0.db3");
  check("db3: db3bag/db3bag_0.db3 and db3bag/metadata.yaml exist", fs.existsSync(dbFile) && fs.existsSync(path.join(out, "metadata.yaml")));
  if (fs.existsSync(dbFile)) {
    sizes.push(["db3bag/db3bag_0.db3", fs.statSync(dbFile).size]);
    const rd = node("read_bag.mjs", [out, "--json"]);
    check("db3: read_bag exit 0", rd.status === 0, rd.stderr.trim());
    if (rd.status === 0) {
      const r = JSON.parse(rd.stdout);
      checkContent("db3", r, { tf: true });
      check("db3: schema table (3, humble)", JSON.stringify(r.schema) === JSON.stringify([{ schema_version: 3, ros_distro: "humble" }]));
      check("db3: metadata.yaml message_count", r.metadata_yaml?.message_count === 3 * N + 1 && r.metadata_yaml?.storage_identifier === "sqlite3");
      check("db3: every topic is cdr", r.topics.every((t) => t.serialization_format === "cdr"));
    }
    if (hasTool("sqlite3")) {
      const q = spawnSync("sqlite3", [dbFile, "PRAGMA integrity_check; SELECT t.name, COUNT(*), MIN(m.timestamp) FROM messages m JOIN topics t ON t.id = m.topic_id GROUP BY t.name ORDER BY t.name;"], { encoding: "utf8" });
      const ns = String(stampNs(stamp0));
      const expLines = ["ok", `/odom|${N}|${ns}`, `/points|${N}|${ns}`, `/tf|${N}|${ns}`, `/tf_static|1|${ns}`];
      check("db3: sqlite3 CLI integrity_check and per-topic counts/first timestamp", q.status === 0 && q.stdout.trim().split("\n").join(";") === expLines.join(";"), q.stdout.trim().split("\n").join("; ") + q.stderr);
    }
  }
}

// errors
{
  const w = node("write_bag.mjs", ["--sequence", path.join(work, "no-such-folder"), "--out", path.join(work, "x.mcap")]);
  check("error: missing folder -> exit 1 with a message", w.status === 1 && /missing sequence folder/.test(w.stderr), w.stderr.trim());
  const bad = path.join(work, "bad-seq");
  fs.rmSync(bad, { recursive: true, force: true });
  fs.mkdirSync(bad);
  const sub = seq.layout === "pcd" ? "scans" : "velodyne";
  fs.symlinkSync(path.resolve(path.dirname(seq.scanPaths[0])), path.join(bad, sub));
  if (seq.layout === "kitti") fs.copyFileSync(path.join(sequence, "calib.txt"), path.join(bad, "calib.txt"));
  const lines = fs.readFileSync(path.join(sequence, "poses.txt"), "utf8").trim().split("\n");
  fs.writeFileSync(path.join(bad, "poses.txt"), lines.slice(0, -1).join("\n") + "\n");
  const w2 = node("write_bag.mjs", ["--sequence", bad, "--out", path.join(work, "x.mcap")]);
  check("error: scans/poses count mismatch -> exit 1 with a message", w2.status === 1 && /scans but \d+ poses/.test(w2.stderr), w2.stderr.trim());
  const w3 = node("write_bag.mjs", ["--sequence", sequence, "--out", path.join(work, "x.mcap"), "--compression", "brotli"]);
  check("error: bad option -> exit 1", w3.status === 1 && /--compression must be/.test(w3.stderr), w3.stderr.split("\n")[0]);
}

// a small synthetic sequence: ascii PCD with mixed types, no times.txt, --stride
{
  const syn = path.join(work, "synthetic");
  fs.rmSync(syn, { recursive: true, force: true });
  fs.mkdirSync(path.join(syn, "scans"), { recursive: true });
  const poses = [];
  for (let k = 0; k < 5; k++) {
    const pts = [[1.5 + k, -2.25, 0.125, 7], [3, 4, 5, 200]];
    fs.writeFileSync(path.join(syn, "scans", `${String(k).padStart(6, "0")}.pcd`),
      "# .PCD v0.7\nVERSION 0.7\nFIELDS x y z intensity label\nSIZE 8 8 8 1 4\nTYPE F F F U U\nCOUNT 1 1 1 1 1\n" +
      `WIDTH ${pts.length}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS ${pts.length}\nDATA ascii\n` +
      pts.map((q) => `${q.join(" ")} 3`).join("\n") + "\n");
    poses.push(`1 0 0 ${k} 0 1 0 0 0 0 1 0`);
  }
  fs.writeFileSync(path.join(syn, "poses.txt"), poses.join("\n") + "\n");
  const out = path.join(work, "synthetic.mcap");
  const w = node("write_bag.mjs", ["--sequence", syn, "--out", out, "--stride", "2", "--field-order", "xyz_ring_i_f64", "--compression", "lz4"]);
  check("synthetic ascii PCD, --stride 2: write_bag exit 0", w.status === 0, (w.stdout + w.stderr).trim());
  const rd = node("read_bag.mjs", [out, "--json"]);
  if (rd.status === 0) {
    const r = JSON.parse(rd.stdout);
    const c = r.first_cloud;
    check("synthetic: 3 scans (0, 2, 4), first point and stamp 0", r.topics.find((t) => t.topic === "/points")?.count === 3 &&
      JSON.stringify(c.first_point) === JSON.stringify({ x: 1.5, y: -2.25, z: 0.125, ring: 0, intensity: 7 }) && c.log_time === "0", JSON.stringify(c.first_point));
  } else check("synthetic: read_bag exit 0", false, rd.stderr);
  const db = path.join(work, "synthetic-db3");
  fs.rmSync(db, { recursive: true, force: true });
  const w2 = node("write_bag.mjs", ["--sequence", syn, "--out", db, "--format", "db3", "--last", "2"]);
  const y = fs.existsSync(path.join(db, "metadata.yaml")) ? fs.readFileSync(path.join(db, "metadata.yaml"), "utf8") : "";
  // scans 3 and 4 without times.txt: 0.3 s and 0.4 s
  check("synthetic db3 --last 2: default times i*0.1 s", w2.status === 0 && /nanoseconds_since_epoch: 300000000\n/.test(y) && /duration:\n    nanoseconds: 100000000\n/.test(y), w2.stderr.trim());
  const pcd = path.join(syn, "scans", "000004.pcd");
  fs.writeFileSync(pcd, fs.readFileSync(pcd, "latin1").replace("DATA ascii", "DATA binary_compressed"));
  const w3 = node("write_bag.mjs", ["--sequence", syn, "--out", out]);
  check("synthetic: binary_compressed PCD -> exit 1 with a message", w3.status === 1 && /binary_compressed is not supported/.test(w3.stderr), w3.stderr.trim());
}

console.log(`files in ${work}: ${sizes.map(([f, s]) => `${f} ${s}`).join(", ")}`);
console.log(`${passed} passed, ${failed} failed`);
process.exit(failed === 0 ? 0 : 1);
