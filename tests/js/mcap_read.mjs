// The official MCAP reader (@mcap/core McapIndexedReader, with @mcap/support's decompressors) reads a bag and
// decodes every message as Foxglove and Lichtblick do (decode.mjs): node mcap_read.mjs BAG
// Prints one JSON line: per topic its schema, encoding, messages read, decoded, and the first decode error.
import { open } from "node:fs/promises";

import * as mcapCore from "@mcap/core";
import * as mcapSupport from "@mcap/support";

import { channelParser } from "./decode.mjs";

const { McapIndexedReader } = mcapCore;
const { loadDecompressHandlers } = mcapSupport;

const handle = await open(process.argv[2], "r");
const size = (await handle.stat()).size;
const readable = {
  size: async () => BigInt(size),
  read: async (offset, length) => {
    const buf = new Uint8Array(Number(length));
    await handle.read(buf, 0, Number(length), Number(offset));
    return buf;
  },
};
const reader = await McapIndexedReader.Initialize({ readable, decompressHandlers: await loadDecompressHandlers() });
const parsers = new Map();
const rows = {};
for (const [id, ch] of reader.channelsById) {
  const schema = reader.schemasById.get(ch.schemaId);
  const row = { schema: schema?.name ?? "", encoding: ch.messageEncoding, read: 0, decoded: 0, error: null };
  rows[ch.topic] = row;
  try {
    parsers.set(id, channelParser(ch.messageEncoding, schema?.name ?? "", schema?.encoding ?? "",
      schema?.data ?? new Uint8Array()));
  } catch (err) {
    row.error = `schema: ${err.message}`;
  }
}
for await (const message of reader.readMessages()) {
  const ch = reader.channelsById.get(message.channelId);
  const row = rows[ch.topic];
  row.read += 1;
  const parse = parsers.get(message.channelId);
  if (!parse) continue;
  try {
    const msg = parse.deserialize(message.data);
    if (msg === undefined || msg === null) throw new Error("decoded to nothing");
    row.decoded += 1;
  } catch (err) {
    row.error ??= `decode: ${err.message}`;
  }
}
await handle.close();
console.log(JSON.stringify({ topics: rows }));
