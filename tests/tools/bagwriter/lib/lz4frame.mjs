// LZ4 *frame* format writer (magic 04 22 4D 18), built on the pure-JS block
// compressor of the npm package lz4js.
//
// Why not lz4js.compress(): it emits 4 MiB blocks whose last match may start
// 10-11 bytes before the block end. liblz4's LZ4F decoder decodes each block
// with an output capacity of the frame's maximum block size, and rejects a
// block whose last match starts less than 12 bytes before that capacity. That
// can only happen for a block of (almost) exactly the maximum size, so this
// writer declares 4 MiB maximum blocks but never fills one: blocks hold at
// most 4 MiB - 64 KiB of input. Blocks are independent (each compressed with
// a fresh hash table) and the frame carries a content checksum (XXH32), as
// the lz4 command line tool writes by default.
import { createRequire } from "node:module";

const require = createRequire(import.meta.url);
const lz4js = require("lz4js");
const xxh32 = require("lz4js/xxh32.js").hash;

const MAGIC = 0x184d2204;
const FLG = 0x40 /* version 01 */ | 0x20 /* independent blocks */ | 0x04 /* content checksum */;
const BD = 7 << 4; /* 4 MiB maximum block size */
const BLOCK_INPUT = 4 * 1024 * 1024 - 64 * 1024;

export function lz4FrameCompress(src) {
  const nBlocks = Math.max(1, Math.ceil(src.length / BLOCK_INPUT));
  // header 7 + per block (4 + payload) + end mark 4 + checksum 4
  const out = new Uint8Array(7 + src.length + nBlocks * 4 + 8);
  const view = new DataView(out.buffer);
  const scratch = new Uint8Array(lz4js.compressBound(BLOCK_INPUT) + 1024);
  let o = 0;
  view.setUint32(o, MAGIC, true); o += 4;
  out[o++] = FLG;
  out[o++] = BD;
  out[o] = (xxh32(0, out, 4, 2) >>> 8) & 0xff; o++;
  for (let s = 0; s < src.length; s += BLOCK_INPUT) {
    const block = src.subarray(s, Math.min(src.length, s + BLOCK_INPUT));
    const hashTable = new Uint32Array(1 << 16);
    const n = lz4js.compressBlock(block, scratch, 0, block.length, hashTable);
    if (n > 0 && n < block.length) {
      view.setUint32(o, n, true); o += 4;
      out.set(scratch.subarray(0, n), o); o += n;
    } else {
      view.setUint32(o, (0x80000000 | block.length) >>> 0, true); o += 4; // stored uncompressed
      out.set(block, o); o += block.length;
    }
  }
  view.setUint32(o, 0, true); o += 4; // end mark
  view.setUint32(o, xxh32(0, src, 0, src.length), true); o += 4;
  return out.subarray(0, o);
}
