#!/usr/bin/env node
// Reads back a bag written by write_bag.mjs (or any ROS 2 MCAP / rosbag2
// sqlite3 bag with these types): prints topics and message counts and decodes
// the first sensor_msgs/msg/PointCloud2 (width, fields, first point) and the
// first nav_msgs/msg/Odometry pose.
//   node read_bag.mjs BAG.mcap | BAGDIR | BAG.db3 [--json] [--dump-chunk FILE]
// --dump-chunk writes the compressed records of the first chunk to FILE, so
// that e.g. `zstd -d` or `lz4 -d` can check the frame independently.
import fs from "node:fs";
import path from "node:path";
import { createRequire } from "node:module";
import { McapIndexedReader, McapStreamReader } from "@mcap/core";
import { parse as parseMsgDef } from "@foxglove/rosmsg";
import { MessageReader } from "@foxglove/rosmsg2-serialization";
import { fullDefinition } from "./lib/msgdefs.mjs";

const require = createRequire(import.meta.url);

async function decompressHandlers() {
  const zstd = require("@foxglove/wasm-zstd");
  const lz4 = require("@foxglove/wasm-lz4");
  await zstd.isLoaded;
  await lz4.isLoaded;
  return {
    zstd: (buf, size) => zstd.decompress(buf, Number(size)),
    lz4: (buf, size) => lz4(buf, Number(size)),
  };
}

const POINT_GETTERS = {
  1: (v, o) => v.getInt8(o), 2: (v, o) => v.getUint8(o),
  3: (v, o, le) => v.getInt16(o, le), 4: (v, o, le) => v.getUint16(o, le),
  5: (v, o, le) => v.getInt32(o, le), 6: (v, o, le) => v.getUint32(o, le),
  7: (v, o, le) => v.getFloat32(o, le), 8: (v, o, le) => v.getFloat64(o, le),
};

function describeCloud(msg) {
  const view = new DataView(msg.data.buffer, msg.data.byteOffset, msg.data.byteLength);
  const first = {};
  for (const f of msg.fields) first[f.name] = POINT_GETTERS[f.datatype](view, f.offset, !msg.is_bigendian);
  return {
    stamp: msg.header.stamp,
    frame_id: msg.header.frame_id,
    height: msg.height,
    width: msg.width,
    fields: msg.fields.map((f) => ({ name: f.name, offset: f.offset, datatype: f.datatype, count: f.count })),
    is_bigendian: msg.is_bigendian,
    point_step: msg.point_step,
    row_step: msg.row_step,
    data_bytes: msg.data.byteLength,
    is_dense: msg.is_dense,
    first_point: first,
  };
}

function describeOdom(msg) {
  return {
    stamp: msg.header.stamp,
    frame_id: msg.header.frame_id,
    child_frame_id: msg.child_frame_id,
    position: msg.pose.pose.position,
    orientation: msg.pose.pose.orientation,
  };
}

// Top-level records of an MCAP file, parsed by hand (independent of @mcap/core)
// to report chunk compression and the first bytes of each chunk's records.
function scanChunks(bytes) {
  const view = new DataView(bytes.buffer, bytes.byteOffset, bytes.byteLength);
  const chunks = [];
  let messagesOutsideChunks = 0;
  let o = 8;
  while (o + 9 <= bytes.length) {
    const op = bytes[o];
    const len = Number(view.getBigUint64(o + 1, true));
    const c = o + 9;
    if (op === 0x02) break; // footer
    if (op === 0x05) messagesOutsideChunks++;
    if (op === 0x06) {
      const uncompressed = Number(view.getBigUint64(c + 16, true));
      const clen = view.getUint32(c + 28, true);
      const compression = new TextDecoder().decode(bytes.subarray(c + 32, c + 32 + clen));
      const rlen = Number(view.getBigUint64(c + 32 + clen, true));
      const recs = bytes.subarray(c + 40 + clen, c + 40 + clen + rlen);
      chunks.push({
        compression, uncompressed_size: uncompressed, compressed_size: rlen,
        magic: Buffer.from(recs.subarray(0, 4)).toString("hex"), records: recs,
      });
    }
    o = c + len;
  }
  return { chunks, messagesOutsideChunks };
}

async function readMcap(file, opts) {
  const bytes = new Uint8Array(fs.readFileSync(file));
  const handlers = await decompressHandlers();
  const out = { file, format: "mcap", bytes: bytes.length };

  // 1) stream reader: every record, CRCs checked
  const stream = new McapStreamReader({ decompressHandlers: handlers, validateCrcs: true });
  stream.append(bytes);
  const schemas = new Map();
  const channels = new Map();
  const counts = new Map();
  const readers = new Map();
  let firstCloud, firstOdom, firstTf, firstTfStatic;
  let rec;
  while ((rec = stream.nextRecord())) {
    if (rec.type === "Header") { out.profile = rec.profile; out.library = rec.library; }
    else if (rec.type === "Schema") schemas.set(rec.id, rec);
    else if (rec.type === "Channel") channels.set(rec.id, rec);
    else if (rec.type === "Message") {
      counts.set(rec.channelId, (counts.get(rec.channelId) ?? 0) + 1);
      const ch = channels.get(rec.channelId);
      const schema = schemas.get(ch.schemaId);
      if (!readers.has(ch.id)) {
        // decode with the definition stored in the file, as a generic reader would
        const text = new TextDecoder().decode(schema.data);
        readers.set(ch.id, new MessageReader(parseMsgDef(text, { ros2: true })));
      }
      const type = schema.name;
      if (type === "sensor_msgs/msg/PointCloud2" && !firstCloud) {
        firstCloud = { ...describeCloud(readers.get(ch.id).readMessage(rec.data)), log_time: String(rec.logTime), topic: ch.topic };
      } else if (type === "nav_msgs/msg/Odometry" && !firstOdom) {
        firstOdom = { ...describeOdom(readers.get(ch.id).readMessage(rec.data)), log_time: String(rec.logTime), topic: ch.topic };
      } else if (type === "tf2_msgs/msg/TFMessage") {
        const m = readers.get(ch.id).readMessage(rec.data).transforms[0];
        const d = { parent: m.header.frame_id, child: m.child_frame_id, translation: m.transform.translation, rotation: m.transform.rotation };
        if (ch.topic === "/tf_static" && !firstTfStatic) firstTfStatic = d;
        if (ch.topic === "/tf" && !firstTf) firstTf = d;
      }
    }
  }
  out.topics = [...channels.values()].map((ch) => ({
    topic: ch.topic,
    type: schemas.get(ch.schemaId)?.name,
    schema_encoding: schemas.get(ch.schemaId)?.encoding,
    message_encoding: ch.messageEncoding,
    count: counts.get(ch.id) ?? 0,
    qos: ch.metadata.get("offered_qos_profiles") !== undefined,
  }));

  // 2) indexed reader (summary section): counts from statistics and from the chunk indexes
  const readable = {
    size: async () => BigInt(bytes.length),
    read: async (offset, length) => bytes.subarray(Number(offset), Number(offset + length)),
  };
  const indexed = await McapIndexedReader.Initialize({ readable, decompressHandlers: handlers });
  out.statistics_counts = Object.fromEntries(
    [...(indexed.statistics?.channelMessageCounts ?? new Map())].map(([id, n]) => [indexed.channelsById.get(id).topic, Number(n)]),
  );
  const idxCounts = {};
  if (indexed.chunkIndexes.length > 0) {
    for await (const m of indexed.readMessages()) {
      const topic = indexed.channelsById.get(m.channelId).topic;
      idxCounts[topic] = (idxCounts[topic] ?? 0) + 1;
    }
  }
  out.indexed_counts = idxCounts;

  // 3) chunks, by hand
  const { chunks, messagesOutsideChunks } = scanChunks(bytes);
  out.chunks = chunks.map(({ records, ...c }) => c);
  out.messages_outside_chunks = messagesOutsideChunks;
  if (opts.dumpChunk) {
    if (chunks.length === 0) throw new Error("--dump-chunk: the file has no chunks");
    fs.writeFileSync(opts.dumpChunk, chunks[0].records);
  }
  out.first_cloud = firstCloud;
  out.first_odom = firstOdom;
  if (firstTf) out.first_tf = firstTf;
  if (firstTfStatic) out.first_tf_static = firstTfStatic;
  return out;
}

async function readDb3(target) {
  let dir = target;
  let dbFile = target;
  if (fs.statSync(target).isDirectory()) {
    const dbs = fs.readdirSync(target).filter((f) => f.endsWith(".db3")).sort();
    if (dbs.length === 0) throw new Error(`${target}: no .db3 file`);
    dbFile = path.join(target, dbs[0]);
  } else {
    dir = path.dirname(target);
  }
  const initSqlJs = require("sql.js");
  const SQL = await initSqlJs();
  const db = new SQL.Database(fs.readFileSync(dbFile));
  const rows = (sql, params) => {
    const st = db.prepare(sql);
    if (params) st.bind(params);
    const r = [];
    while (st.step()) r.push(st.get(null, { useBigInt: true }));
    st.free();
    return r;
  };
  const out = { file: dbFile, format: "db3", bytes: fs.statSync(dbFile).size };
  out.schema = rows("SELECT schema_version, ros_distro FROM schema").map(([v, d]) => ({ schema_version: Number(v), ros_distro: d }));
  const topics = rows("SELECT id, name, type, serialization_format FROM topics ORDER BY id");
  out.topics = topics.map(([id, name, type, fmt]) => ({
    topic: name, type, serialization_format: fmt,
    count: Number(rows("SELECT COUNT(*) FROM messages WHERE topic_id = ?", [id])[0][0]),
  }));
  const first = (type, topic) => {
    const t = topics.find((r) => r[2] === type && (topic === undefined || r[1] === topic));
    if (!t) return undefined;
    const [[ts, data]] = rows("SELECT timestamp, data FROM messages WHERE topic_id = ? ORDER BY timestamp, id LIMIT 1", [t[0]]);
    const reader = new MessageReader(parseMsgDef(fullDefinition(type), { ros2: true }));
    return { ts: String(ts), msg: reader.readMessage(data), topic: t[1] };
  };
  const c = first("sensor_msgs/msg/PointCloud2");
  if (c) out.first_cloud = { ...describeCloud(c.msg), log_time: c.ts, topic: c.topic };
  const od = first("nav_msgs/msg/Odometry");
  if (od) out.first_odom = { ...describeOdom(od.msg), log_time: od.ts, topic: od.topic };
  for (const [topic, key] of [["/tf", "first_tf"], ["/tf_static", "first_tf_static"]]) {
    const m = first("tf2_msgs/msg/TFMessage", topic)?.msg.transforms[0];
    if (m) out[key] = { parent: m.header.frame_id, child: m.child_frame_id, translation: m.transform.translation, rotation: m.transform.rotation };
  }
  out.metadata_rows = Number(rows("SELECT COUNT(*) FROM metadata")[0][0]);
  db.close();
  const meta = path.join(dir, "metadata.yaml");
  if (fs.existsSync(meta)) {
    const y = fs.readFileSync(meta, "utf8");
    const m = y.match(/^  message_count: (\d+)$/m);
    out.metadata_yaml = { message_count: m ? Number(m[1]) : null, storage_identifier: (y.match(/storage_identifier: (\S+)/) || [])[1] };
  }
  return out;
}

function printHuman(r) {
  console.log(`${r.file}: ${r.format}, ${r.bytes} bytes${r.profile !== undefined ? `, profile '${r.profile}', library '${r.library}'` : ""}`);
  if (r.schema) console.log(`  schema table: ${JSON.stringify(r.schema)}`);
  for (const t of r.topics) console.log(`  ${t.topic}  ${t.type}  ${t.count} messages`);
  if (r.chunks) {
    const kinds = {};
    for (const c of r.chunks) {
      const k = `${c.compression || "none"} (magic ${c.magic})`;
      kinds[k] = (kinds[k] ?? 0) + 1;
    }
    console.log(`  chunks: ${r.chunks.length} ${JSON.stringify(kinds)}; messages outside chunks: ${r.messages_outside_chunks}`);
    console.log(`  statistics: ${JSON.stringify(r.statistics_counts)}; via chunk index: ${JSON.stringify(r.indexed_counts)}`);
  }
  if (r.metadata_yaml) console.log(`  metadata.yaml: ${JSON.stringify(r.metadata_yaml)}; metadata table rows: ${r.metadata_rows}`);
  const c = r.first_cloud;
  if (c) {
    console.log(`  first PointCloud2 on ${c.topic} at ${c.log_time} ns: stamp ${c.stamp.sec}.${String(c.stamp.nanosec).padStart(9, "0")}, frame '${c.frame_id}', height ${c.height}, width ${c.width}, point_step ${c.point_step}, row_step ${c.row_step}, bigendian ${c.is_bigendian}, dense ${c.is_dense}`);
    console.log(`    fields: ${c.fields.map((f) => `${f.name}@${f.offset}:${f.datatype}x${f.count}`).join(" ")}`);
    console.log(`    first point: ${JSON.stringify(c.first_point)}`);
  }
  const o = r.first_odom;
  if (o) console.log(`  first Odometry on ${o.topic}: ${o.frame_id} -> ${o.child_frame_id}, position ${JSON.stringify(o.position)}, orientation ${JSON.stringify(o.orientation)}`);
  if (r.first_tf) console.log(`  first /tf: ${r.first_tf.parent} -> ${r.first_tf.child}`);
  if (r.first_tf_static) console.log(`  first /tf_static: ${r.first_tf_static.parent} -> ${r.first_tf_static.child}`);
}

async function main() {
  const args = process.argv.slice(2);
  const opts = { json: false };
  let target;
  for (let i = 0; i < args.length; i++) {
    if (args[i] === "--json") opts.json = true;
    else if (args[i] === "--dump-chunk") opts.dumpChunk = args[++i];
    else if (!target) target = args[i];
    else throw new Error(`unexpected argument '${args[i]}'`);
  }
  if (!target) throw new Error("usage: node read_bag.mjs BAG.mcap|BAGDIR|BAG.db3 [--json] [--dump-chunk FILE]");
  if (!fs.existsSync(target)) throw new Error(`no such file or folder: ${target}`);
  const isDb3 = fs.statSync(target).isDirectory() || target.endsWith(".db3");
  const r = isDb3 ? await readDb3(target) : await readMcap(target, opts);
  if (opts.json) console.log(JSON.stringify(r, null, 1));
  else printHuman(r);
}

main().catch((err) => {
  console.error(`read_bag: error: ${err && err.message ? err.message : err}`);
  process.exit(1);
});
