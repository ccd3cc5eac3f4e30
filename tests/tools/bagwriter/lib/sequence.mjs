// Reads a sequence folder as the segmatch project writes them:
//   DIR/scans/NNNNNN.pcd (or DIR/NNNNNN.pcd) + poses.txt (T_world_lidar, 3x4 row-major)
//   DIR/velodyne/NNNNNN.bin (KITTI) + poses.txt (camera-0 frame) + calib.txt (Tr)
//   DIR/times.txt optional: seconds per scan; without it scan i is at i * 0.1 s.
import fs from "node:fs";
import path from "node:path";

export class InputError extends Error {}

function fail(msg) {
  throw new InputError(msg);
}

function listFiles(dir, ext) {
  if (!fs.existsSync(dir) || !fs.statSync(dir).isDirectory()) return [];
  return fs
    .readdirSync(dir)
    .filter((f) => f.endsWith(ext))
    .sort()
    .map((f) => path.join(dir, f));
}

// ---- scans ---------------------------------------------------------------

const PCD_READERS = {
  F4: (v, o) => v.getFloat32(o, true),
  F8: (v, o) => v.getFloat64(o, true),
  U1: (v, o) => v.getUint8(o),
  U2: (v, o) => v.getUint16(o, true),
  U4: (v, o) => v.getUint32(o, true),
  U8: (v, o) => Number(v.getBigUint64(o, true)),
  I1: (v, o) => v.getInt8(o),
  I2: (v, o) => v.getInt16(o, true),
  I4: (v, o) => v.getInt32(o, true),
  I8: (v, o) => Number(v.getBigInt64(o, true)),
};

/** Returns { n, xyzi: Float64Array(4n) } with x, y, z, intensity per point. */
export function readPcd(file) {
  const buf = fs.readFileSync(file);
  const hdr = {};
  let pos = 0;
  let data = null;
  while (pos < buf.length) {
    let eol = buf.indexOf(0x0a, pos);
    if (eol < 0) eol = buf.length;
    const line = buf.toString("latin1", pos, eol).replace(/\r$/, "").trim();
    pos = eol + 1;
    if (line === "" || line.startsWith("#")) continue;
    const [key, ...rest] = line.split(/\s+/);
    hdr[key.toUpperCase()] = rest;
    if (key.toUpperCase() === "DATA") {
      data = (rest[0] || "").toLowerCase();
      break;
    }
  }
  if (data === null) fail(`${file}: no DATA line in the PCD header`);
  if (data === "binary_compressed") {
    fail(`${file}: DATA binary_compressed is not supported by this tool (use binary or ascii PCD)`);
  }
  if (data !== "binary" && data !== "ascii") fail(`${file}: unknown PCD DATA kind '${data}'`);
  const names = hdr.FIELDS;
  if (!names) fail(`${file}: no FIELDS line`);
  const nf = names.length;
  const sizes = (hdr.SIZE || []).map(Number);
  const types = (hdr.TYPE || []).map((t) => t.toUpperCase());
  const counts = hdr.COUNT ? hdr.COUNT.map(Number) : names.map(() => 1);
  if (sizes.length !== nf || types.length !== nf || counts.length !== nf) {
    fail(`${file}: FIELDS, SIZE, TYPE and COUNT have different lengths`);
  }
  const width = Number((hdr.WIDTH || [])[0]);
  const height = Number((hdr.HEIGHT || ["1"])[0]);
  let n = width * height;
  if (!Number.isInteger(n) || n < 0) {
    n = Number((hdr.POINTS || [])[0]);
    if (!Number.isInteger(n) || n < 0) fail(`${file}: bad WIDTH/HEIGHT/POINTS`);
  }
  // element offset of each field, in bytes (binary) and in tokens (ascii)
  const off = [];
  const tok = [];
  let step = 0;
  let ntok = 0;
  for (let k = 0; k < nf; k++) {
    off.push(step);
    tok.push(ntok);
    step += sizes[k] * counts[k];
    ntok += counts[k];
  }
  const want = ["x", "y", "z", "intensity"];
  const idx = want.map((w) => names.indexOf(w));
  if (idx[3] < 0) idx[3] = names.indexOf("i");
  for (let k = 0; k < 3; k++) if (idx[k] < 0) fail(`${file}: PCD has no '${want[k]}' field`);
  const xyzi = new Float64Array(4 * n);
  if (data === "binary") {
    const body = buf.subarray(pos);
    if (body.length < n * step) {
      fail(`${file}: DATA binary holds ${body.length} bytes, ${n} points of ${step} bytes need ${n * step}`);
    }
    const view = new DataView(body.buffer, body.byteOffset, n * step);
    const readers = idx.map((k) => {
      if (k < 0) return null;
      const r = PCD_READERS[types[k] + sizes[k]];
      if (!r) fail(`${file}: unsupported TYPE ${types[k]} SIZE ${sizes[k]} for field ${names[k]}`);
      return r;
    });
    for (let p = 0; p < n; p++) {
      const base = p * step;
      for (let c = 0; c < 4; c++) {
        xyzi[4 * p + c] = readers[c] ? readers[c](view, base + off[idx[c]]) : 0;
      }
    }
  } else {
    const lines = buf.toString("latin1", pos).split("\n").map((l) => l.trim()).filter((l) => l !== "");
    if (lines.length < n) fail(`${file}: DATA ascii has ${lines.length} lines, expected ${n}`);
    for (let p = 0; p < n; p++) {
      const t = lines[p].split(/\s+/);
      if (t.length < ntok) fail(`${file}: ascii point ${p} has ${t.length} values, expected ${ntok}`);
      for (let c = 0; c < 4; c++) {
        xyzi[4 * p + c] = idx[c] < 0 ? 0 : Number(t[tok[idx[c]]]);
      }
    }
  }
  return { n, xyzi };
}

export function readKittiBin(file) {
  const buf = fs.readFileSync(file);
  if (buf.length % 16 !== 0) fail(`${file}: size ${buf.length} is not a multiple of 16 (x y z intensity float32)`);
  const n = buf.length / 16;
  const view = new DataView(buf.buffer, buf.byteOffset, buf.length);
  const xyzi = new Float64Array(4 * n);
  for (let k = 0; k < 4 * n; k++) xyzi[k] = view.getFloat32(4 * k, true);
  return { n, xyzi };
}

// ---- poses and times -----------------------------------------------------

function readMatrices(file) {
  const out = [];
  fs.readFileSync(file, "utf8").split("\n").forEach((line, i) => {
    const t = line.trim();
    if (t === "" || t.startsWith("#")) return;
    const v = t.split(/\s+/).map(Number);
    if (v.length !== 12 || v.some((x) => !Number.isFinite(x))) {
      fail(`${file}:${i + 1}: expected 12 numbers (row-major 3x4 matrix), got '${t.slice(0, 80)}'`);
    }
    out.push(v);
  });
  return out;
}

// 3x4 row-major arrays as rigid transforms
function mul(a, b) {
  const r = new Array(12);
  for (let i = 0; i < 3; i++) {
    for (let j = 0; j < 4; j++) {
      let s = j === 3 ? a[4 * i + 3] : 0;
      for (let k = 0; k < 3; k++) s += a[4 * i + k] * b[4 * k + j];
      r[4 * i + j] = s;
    }
  }
  return r;
}

function invRigid(a) {
  // [R t]^-1 = [R^T -R^T t]
  const r = new Array(12);
  for (let i = 0; i < 3; i++) {
    for (let k = 0; k < 3; k++) r[4 * i + k] = a[4 * k + i];
    r[4 * i + 3] = -(a[i] * a[3] + a[4 + i] * a[7] + a[8 + i] * a[11]);
  }
  return r;
}

function readCalibTr(file) {
  for (const line of fs.readFileSync(file, "utf8").split("\n")) {
    const m = line.match(/^\s*(Tr|Tr_velo_to_cam)\s*:\s*(.*)$/);
    if (!m) continue;
    const v = m[2].trim().split(/\s+/).map(Number);
    if (v.length !== 12 || v.some((x) => !Number.isFinite(x))) fail(`${file}: '${m[1]}:' needs 12 numbers`);
    return v;
  }
  fail(`${file}: no 'Tr:' (or 'Tr_velo_to_cam:') line`);
}

/** "1565943695.2280283" -> { sec, nanosec } exactly (no float rounding). */
export function parseStamp(text, where) {
  const m = text.match(/^(\d+)(?:\.(\d*))?$/);
  if (m) {
    const frac = (m[2] || "").padEnd(10, "0");
    let sec = Number(m[1]);
    let nanosec = Number(frac.slice(0, 9));
    if (Number(frac[9]) >= 5) nanosec += 1; // round half up at 1 ns
    if (nanosec >= 1e9) { sec += 1; nanosec -= 1e9; }
    if (sec > 2147483647) fail(`${where}: time ${text} does not fit builtin_interfaces/Time`);
    return { sec, nanosec };
  }
  const x = Number(text);
  if (!Number.isFinite(x) || x < 0) fail(`${where}: '${text}' is not a non-negative time in seconds`);
  let sec = Math.floor(x);
  let nanosec = Math.round((x - sec) * 1e9);
  if (nanosec >= 1e9) { sec += 1; nanosec -= 1e9; }
  return { sec, nanosec };
}

export function stampNs(stamp) {
  return BigInt(stamp.sec) * 1000000000n + BigInt(stamp.nanosec);
}

function readTimes(file) {
  const out = [];
  fs.readFileSync(file, "utf8").split("\n").forEach((line, i) => {
    const t = line.trim();
    if (t === "" || t.startsWith("#")) return;
    out.push(parseStamp(t.split(/\s+/)[0], `${file}:${i + 1}`));
  });
  return out;
}

// ---- the sequence ----------------------------------------------------------

/**
 * Opens DIR. Returns { layout, scanPaths, poses (T_world_lidar, 3x4 row-major
 * per scan), stamps ({sec, nanosec} per scan), hasTimes, readScan(i) }.
 */
export function openSequence(dir) {
  if (!fs.existsSync(dir)) fail(`missing sequence folder: ${dir}`);
  if (!fs.statSync(dir).isDirectory()) fail(`not a folder: ${dir}`);
  let layout = "kitti";
  let scanPaths = listFiles(path.join(dir, "velodyne"), ".bin");
  if (scanPaths.length === 0) {
    layout = "pcd";
    scanPaths = listFiles(path.join(dir, "scans"), ".pcd");
    if (scanPaths.length === 0) scanPaths = listFiles(dir, ".pcd");
    if (scanPaths.length === 0) fail(`${dir}: no scans found: expected velodyne/NNNNNN.bin or scans/NNNNNN.pcd`);
  }
  const n = scanPaths.length;
  const posesPath = path.join(dir, "poses.txt");
  if (!fs.existsSync(posesPath)) fail(`${dir}: missing poses.txt (a sequence needs one pose per scan)`);
  let poses = readMatrices(posesPath);
  if (poses.length !== n) fail(`${dir}: ${n} scans but ${poses.length} poses in poses.txt`);
  if (layout === "kitti") {
    // KITTI poses are camera-0 poses: T_world_lidar = Tr^-1 * P * Tr
    const calibPath = path.join(dir, "calib.txt");
    if (!fs.existsSync(calibPath)) fail(`${dir}: missing calib.txt (needed to turn camera-frame poses into LiDAR poses)`);
    const tr = readCalibTr(calibPath);
    const trInv = invRigid(tr);
    poses = poses.map((p) => mul(mul(trInv, p), tr));
  }
  const timesPath = path.join(dir, "times.txt");
  const hasTimes = fs.existsSync(timesPath);
  let stamps;
  if (hasTimes) {
    stamps = readTimes(timesPath);
    if (stamps.length !== n) fail(`${dir}: ${n} scans but ${stamps.length} times in times.txt`);
  } else {
    // i * 0.1 s, exactly
    stamps = scanPaths.map((_, i) => ({ sec: Math.floor(i / 10), nanosec: (i % 10) * 100000000 }));
  }
  const readScan = (i) => (layout === "pcd" ? readPcd(scanPaths[i]) : readKittiBin(scanPaths[i]));
  return { layout, scanPaths, poses, stamps, hasTimes, readScan };
}

/** Rotation part of a 3x4 row-major matrix -> unit quaternion {x, y, z, w}, w >= 0. */
export function quaternionFromMatrix(m) {
  const r00 = m[0], r01 = m[1], r02 = m[2];
  const r10 = m[4], r11 = m[5], r12 = m[6];
  const r20 = m[8], r21 = m[9], r22 = m[10];
  const tr = r00 + r11 + r22;
  let x, y, z, w;
  if (tr > 0) {
    const s = Math.sqrt(tr + 1) * 2;
    w = 0.25 * s; x = (r21 - r12) / s; y = (r02 - r20) / s; z = (r10 - r01) / s;
  } else if (r00 > r11 && r00 > r22) {
    const s = Math.sqrt(1 + r00 - r11 - r22) * 2;
    w = (r21 - r12) / s; x = 0.25 * s; y = (r01 + r10) / s; z = (r02 + r20) / s;
  } else if (r11 > r22) {
    const s = Math.sqrt(1 + r11 - r00 - r22) * 2;
    w = (r02 - r20) / s; x = (r01 + r10) / s; y = 0.25 * s; z = (r12 + r21) / s;
  } else {
    const s = Math.sqrt(1 + r22 - r00 - r11) * 2;
    w = (r10 - r01) / s; x = (r02 + r20) / s; y = (r12 + r21) / s; z = 0.25 * s;
  }
  const norm = Math.hypot(x, y, z, w) * (w < 0 ? -1 : 1);
  return { x: x / norm, y: y / norm, z: z / norm, w: w / norm };
}
