#!/usr/bin/env node
// Independent ROS 2 bag writer (MCAP via @mcap/core, or rosbag2 sqlite3 .db3
// via sql.js; CDR via @foxglove/rosmsg2-serialization) for the
// interoperability tests of segmatch's C++ bag reader. See README.md.
import fs from "node:fs";
import path from "node:path";
import { createRequire } from "node:module";
import { McapWriter } from "@mcap/core";
import { parse as parseMsgDef } from "@foxglove/rosmsg";
import { MessageWriter } from "@foxglove/rosmsg2-serialization";
import { fullDefinition, qosYaml, POINTFIELD } from "./lib/msgdefs.mjs";
import { lz4FrameCompress } from "./lib/lz4frame.mjs";
import { InputError, openSequence, quaternionFromMatrix, stampNs } from "./lib/sequence.mjs";

const require = createRequire(import.meta.url);

const USAGE = `usage: node write_bag.mjs --sequence DIR --out FILE [--format mcap|db3]
         [--compression zstd|lz4|none] [--unchunked] [--chunk-size BYTES]
         [--field-order xyzi|ixyz|xyz_ring_i_f64] [--points-topic /points]
         [--odom-topic /odom] [--frame-id lidar] [--map-frame map] [--tf]
         [--stride N] [--last N]
  --format db3: --out is a folder; writes OUT/<basename>_0.db3 and OUT/metadata.yaml
  --stride N keeps scans 0, N, 2N, ...; then --last N keeps the last N of those`;

class UsageError extends Error {}

function parseArgs(argv) {
  const o = {
    format: "mcap", compression: "zstd", unchunked: false, chunkSize: 4 * 1024 * 1024,
    fieldOrder: "xyzi", pointsTopic: "/points", odomTopic: "/odom", frameId: "lidar",
    mapFrame: "map", tf: false, stride: 1, last: 0,
  };
  const valued = {
    "--sequence": "sequence", "--out": "out", "--format": "format", "--compression": "compression",
    "--field-order": "fieldOrder", "--points-topic": "pointsTopic", "--odom-topic": "odomTopic",
    "--frame-id": "frameId", "--map-frame": "mapFrame", "--stride": "stride", "--last": "last",
    "--chunk-size": "chunkSize",
  };
  for (let i = 0; i < argv.length; i++) {
    let a = argv[i];
    let v;
    const eq = a.indexOf("=");
    if (a.startsWith("--") && eq > 0) { v = a.slice(eq + 1); a = a.slice(0, eq); }
    if (a === "-h" || a === "--help") { console.log(USAGE); process.exit(0); }
    if (a === "--unchunked") { o.unchunked = true; continue; }
    if (a === "--tf") { o.tf = true; continue; }
    const key = valued[a];
    if (!key) throw new UsageError(`unknown option '${a}'`);
    if (v === undefined) {
      if (i + 1 >= argv.length) throw new UsageError(`${a} needs a value`);
      v = argv[++i];
    }
    o[key] = v;
  }
  if (!o.sequence) throw new UsageError("--sequence DIR is required");
  if (!o.out) throw new UsageError("--out is required");
  if (!["mcap", "db3"].includes(o.format)) throw new UsageError(`--format must be mcap or db3, not '${o.format}'`);
  if (!["zstd", "lz4", "none"].includes(o.compression)) throw new UsageError(`--compression must be zstd, lz4 or none, not '${o.compression}'`);
  if (!["xyzi", "ixyz", "xyz_ring_i_f64"].includes(o.fieldOrder)) throw new UsageError(`--field-order must be xyzi, ixyz or xyz_ring_i_f64, not '${o.fieldOrder}'`);
  for (const k of ["stride", "last", "chunkSize"]) {
    const n = Number(o[k]);
    if (!Number.isInteger(n) || n < 0 || (k !== "last" && n < 1)) throw new UsageError(`bad value for --${k.replace(/[A-Z]/g, (c) => "-" + c.toLowerCase())}: '${o[k]}'`);
    o[k] = n;
  }
  for (const k of ["pointsTopic", "odomTopic"]) if (!o[k].startsWith("/")) o[k] = "/" + o[k];
  return o;
}

// ---- point layouts ----------------------------------------------------------

const F32 = POINTFIELD.FLOAT32;
const F64 = POINTFIELD.FLOAT64;
const LAYOUTS = {
  xyzi: {
    pointStep: 16,
    fields: [["x", 0, F32], ["y", 4, F32], ["z", 8, F32], ["intensity", 12, F32]],
    write(v, o, x, y, z, i) { v.setFloat32(o, x, true); v.setFloat32(o + 4, y, true); v.setFloat32(o + 8, z, true); v.setFloat32(o + 12, i, true); },
  },
  ixyz: {
    pointStep: 16,
    fields: [["intensity", 0, F32], ["x", 4, F32], ["y", 8, F32], ["z", 12, F32]],
    write(v, o, x, y, z, i) { v.setFloat32(o, i, true); v.setFloat32(o + 4, x, true); v.setFloat32(o + 8, y, true); v.setFloat32(o + 12, z, true); },
  },
  xyz_ring_i_f64: {
    pointStep: 32,
    fields: [["x", 0, F64], ["y", 8, F64], ["z", 16, F64], ["ring", 24, POINTFIELD.UINT16], ["intensity", 28, F32]],
    // ring: point index modulo 64 (any integer is fine; bytes 26..27 are padding = 0)
    write(v, o, x, y, z, i, p) { v.setFloat64(o, x, true); v.setFloat64(o + 8, y, true); v.setFloat64(o + 16, z, true); v.setUint16(o + 24, p % 64, true); v.setFloat32(o + 28, i, true); },
  },
};

function pointCloud2(scan, layout, stamp, frameId) {
  const { n, xyzi } = scan;
  const data = new Uint8Array(n * layout.pointStep);
  const view = new DataView(data.buffer);
  for (let p = 0; p < n; p++) {
    layout.write(view, p * layout.pointStep, xyzi[4 * p], xyzi[4 * p + 1], xyzi[4 * p + 2], xyzi[4 * p + 3], p);
  }
  return {
    header: { stamp, frame_id: frameId },
    height: 1,
    width: n,
    fields: layout.fields.map(([name, offset, datatype]) => ({ name, offset, datatype, count: 1 })),
    is_bigendian: false,
    point_step: layout.pointStep,
    row_step: layout.pointStep * n,
    data,
    is_dense: true,
  };
}

function poseOf(m) {
  return { position: { x: m[3], y: m[7], z: m[11] }, orientation: quaternionFromMatrix(m) };
}

// ---- output sinks -------------------------------------------------------------

class FileWritable {
  constructor(fd) { this.fd = fd; this.pos = 0n; }
  async write(buf) {
    let done = 0;
    while (done < buf.byteLength) {
      const { bytesWritten } = await this.fd.write(buf, done, buf.byteLength - done);
      done += bytesWritten;
    }
    this.pos += BigInt(buf.byteLength);
  }
  position() { return this.pos; }
}

async function mcapSink(opts) {
  let compressChunk;
  if (opts.compression === "zstd") {
    const zstd = require("@foxglove/wasm-zstd");
    await zstd.isLoaded;
    compressChunk = (data) => ({ compression: "zstd", compressedData: zstd.compress(data, 3) });
  } else if (opts.compression === "lz4") {
    compressChunk = (data) => ({ compression: "lz4", compressedData: lz4FrameCompress(data) });
  }
  fs.mkdirSync(path.dirname(path.resolve(opts.out)), { recursive: true });
  const fd = await fs.promises.open(opts.out, "w");
  const writable = new FileWritable(fd);
  const writer = new McapWriter({
    writable,
    useChunks: !opts.unchunked,
    chunkSize: opts.chunkSize,
    compressChunk: opts.unchunked ? undefined : compressChunk,
  });
  const { LIBRARY_IDENTIFIER } = await import("@mcap/core");
  await writer.start({ profile: "ros2", library: `segmatch-bagwriter; ${LIBRARY_IDENTIFIER}` });
  const seq = new Map();
  return {
    files: [opts.out],
    async addTopic(t) {
      const schemaId = await writer.registerSchema({
        name: t.type, encoding: "ros2msg", data: new TextEncoder().encode(t.definition),
      });
      t.channelId = await writer.registerChannel({
        topic: t.name, schemaId, messageEncoding: "cdr",
        metadata: new Map([["offered_qos_profiles", t.qos]]),
      });
      seq.set(t.channelId, 0);
    },
    async addMessage(t, ns, bytes) {
      const s = seq.get(t.channelId);
      seq.set(t.channelId, s + 1);
      await writer.addMessage({ channelId: t.channelId, sequence: s, logTime: ns, publishTime: ns, data: bytes });
    },
    async close() {
      await writer.end();
      await fd.close();
    },
  };
}

async function db3Sink(opts) {
  const initSqlJs = require("sql.js");
  const SQL = await initSqlJs();
  const dir = opts.out.replace(/\/+$/, "");
  const base = path.basename(path.resolve(dir));
  if (fs.existsSync(dir) && !fs.statSync(dir).isDirectory()) {
    throw new InputError(`--format db3 writes a folder, but ${dir} is a file`);
  }
  fs.mkdirSync(dir, { recursive: true });
  const dbName = `${base}_0.db3`;
  const db = new SQL.Database();
  db.run(
    "CREATE TABLE schema(schema_version INTEGER PRIMARY KEY,ros_distro TEXT NOT NULL);" +
    "CREATE TABLE metadata(id INTEGER PRIMARY KEY,metadata_version INTEGER NOT NULL,metadata TEXT NOT NULL);" +
    "CREATE TABLE topics(id INTEGER PRIMARY KEY,name TEXT NOT NULL,type TEXT NOT NULL,serialization_format TEXT NOT NULL,offered_qos_profiles TEXT NOT NULL);" +
    "CREATE TABLE messages(id INTEGER PRIMARY KEY,topic_id INTEGER NOT NULL,timestamp INTEGER NOT NULL, data BLOB NOT NULL);" +
    "CREATE INDEX timestamp_idx ON messages (timestamp ASC);",
  );
  db.run("INSERT INTO schema(schema_version, ros_distro) VALUES (3, 'humble')");
  db.run("BEGIN TRANSACTION");
  const insert = db.prepare("INSERT INTO messages (timestamp, topic_id, data) VALUES (?, ?, ?)");
  const topics = [];
  let nextId = 1;
  let start = null;
  let end = null;
  return {
    files: [path.join(dir, dbName), path.join(dir, "metadata.yaml")],
    async addTopic(t) {
      t.topicId = nextId++;
      t.count = 0;
      topics.push(t);
      db.run(
        "INSERT INTO topics (id, name, type, serialization_format, offered_qos_profiles) VALUES (?, ?, ?, 'cdr', ?)",
        [t.topicId, t.name, t.type, t.qos],
      );
    },
    async addMessage(t, ns, bytes) {
      insert.run([ns, t.topicId, bytes]); // BigInt binds as a 64-bit integer
      t.count++;
      if (start === null || ns < start) start = ns;
      if (end === null || ns > end) end = ns;
    },
    async close() {
      insert.free();
      db.run("COMMIT");
      const total = topics.reduce((s, t) => s + t.count, 0);
      const yaml = metadataYaml({ dbName, topics, start: start ?? 0n, end: end ?? 0n, total });
      db.run("INSERT INTO metadata (metadata_version, metadata) VALUES (5, ?)", [yaml]);
      fs.writeFileSync(path.join(dir, dbName), db.export());
      db.close();
      fs.writeFileSync(path.join(dir, "metadata.yaml"), yaml);
    },
  };
}

function metadataYaml({ dbName, topics, start, end, total }) {
  const q = (s) => JSON.stringify(s); // a JSON string is a valid YAML double-quoted scalar
  const dur = end - start;
  let y = "rosbag2_bagfile_information:\n";
  y += "  version: 5\n";
  y += "  storage_identifier: sqlite3\n";
  y += "  duration:\n";
  y += `    nanoseconds: ${dur}\n`;
  y += "  starting_time:\n";
  y += `    nanoseconds_since_epoch: ${start}\n`;
  y += `  message_count: ${total}\n`;
  y += "  topics_with_message_count:\n";
  for (const t of topics) {
    y += "    - topic_metadata:\n";
    y += `        name: ${t.name}\n`;
    y += `        type: ${t.type}\n`;
    y += "        serialization_format: cdr\n";
    y += `        offered_qos_profiles: ${q(t.qos)}\n`;
    y += `      message_count: ${t.count}\n`;
  }
  y += '  compression_format: ""\n';
  y += '  compression_mode: ""\n';
  y += "  relative_file_paths:\n";
  y += `    - ${dbName}\n`;
  y += "  files:\n";
  y += `    - path: ${dbName}\n`;
  y += "      starting_time:\n";
  y += `        nanoseconds_since_epoch: ${start}\n`;
  y += "      duration:\n";
  y += `        nanoseconds: ${dur}\n`;
  y += `      message_count: ${total}\n`;
  return y;
}

// ---- main -----------------------------------------------------------------------

async function main() {
  const t0 = process.hrtime.bigint();
  const opts = parseArgs(process.argv.slice(2));
  const seqn = openSequence(opts.sequence);
  let indices = seqn.scanPaths.map((_, i) => i).filter((i) => i % opts.stride === 0);
  if (opts.last > 0) indices = indices.slice(-opts.last);
  if (indices.length === 0) throw new InputError("no scans selected");
  const layout = LAYOUTS[opts.fieldOrder];

  const mkTopic = (name, type, qos) => {
    const definition = fullDefinition(type);
    const writer = new MessageWriter(parseMsgDef(definition, { ros2: true }));
    return { name, type, definition, qos, writer, written: 0 };
  };
  const points = mkTopic(opts.pointsTopic, "sensor_msgs/msg/PointCloud2", qosYaml({ reliability: 2 }));
  const odom = mkTopic(opts.odomTopic, "nav_msgs/msg/Odometry", qosYaml());
  const topics = [points, odom];
  let tf, tfStatic;
  if (opts.tf) {
    tf = mkTopic("/tf", "tf2_msgs/msg/TFMessage", qosYaml());
    tfStatic = mkTopic("/tf_static", "tf2_msgs/msg/TFMessage", qosYaml({ durability: 1 }));
    topics.push(tf, tfStatic);
  }

  const sink = opts.format === "mcap" ? await mcapSink(opts) : await db3Sink(opts);
  for (const t of topics) await sink.addTopic(t);
  const put = async (t, ns, msg) => {
    await sink.addMessage(t, ns, t.writer.writeMessage(msg));
    t.written++;
  };

  for (const [k, i] of indices.entries()) {
    const stamp = seqn.stamps[i];
    const ns = stampNs(stamp);
    const pose = poseOf(seqn.poses[i]);
    if (opts.tf && k === 0) {
      await put(tfStatic, ns, {
        transforms: [{
          header: { stamp, frame_id: opts.frameId },
          child_frame_id: `${opts.frameId}_optical`,
          transform: { translation: { x: 0, y: 0, z: 0 }, rotation: { x: 0, y: 0, z: 0, w: 1 } },
        }],
      });
    }
    await put(points, ns, pointCloud2(seqn.readScan(i), layout, stamp, opts.frameId));
    await put(odom, ns, {
      header: { stamp, frame_id: opts.mapFrame },
      child_frame_id: opts.frameId,
      pose: { pose, covariance: new Array(36).fill(0) },
      twist: { twist: { linear: { x: 0, y: 0, z: 0 }, angular: { x: 0, y: 0, z: 0 } }, covariance: new Array(36).fill(0) },
    });
    if (opts.tf) {
      await put(tf, ns, {
        transforms: [{
          header: { stamp, frame_id: opts.mapFrame },
          child_frame_id: opts.frameId,
          transform: { translation: pose.position, rotation: pose.orientation },
        }],
      });
    }
  }
  await sink.close();

  const bytes = sink.files.reduce((s, f) => s + fs.statSync(f).size, 0);
  const secs = Number(process.hrtime.bigint() - t0) / 1e9;
  const mode = opts.format === "mcap"
    ? `mcap, ${opts.unchunked ? "unchunked" : `chunked ${opts.compression}`}`
    : "db3";
  console.log(
    `wrote ${sink.files[0]} (${mode}, ${opts.fieldOrder}, scans ${indices[0]}..${indices[indices.length - 1]} of ${seqn.layout} sequence): ` +
    topics.map((t) => `${t.name} ${t.written}`).join(", ") +
    `; ${bytes} bytes; ${secs.toFixed(2)} s`,
  );
}

main().catch((err) => {
  if (err instanceof UsageError) {
    console.error(`write_bag: ${err.message}\n${USAGE}`);
  } else if (err instanceof InputError) {
    console.error(`write_bag: error: ${err.message}`);
  } else {
    console.error(`write_bag: error: ${err && err.stack ? err.stack : err}`);
  }
  process.exit(1);
});
