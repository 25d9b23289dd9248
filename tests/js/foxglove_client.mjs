// The official Foxglove WebSocket client (@foxglove/ws-protocol) against a live view, decoding as the viewers do
// (decode.mjs): node foxglove_client.mjs PORT SUBPROTOCOL SECONDS
// Subscribes to every advertised channel and prints one JSON line: the subprotocol agreed, the server's
// capabilities, the server times it broadcast (count, first and last, ns as strings), and per channel its schema,
// encoding, messages decoded and the first decode error. Exit 0 once every channel decoded a message and, when
// the server offers "time", two times arrived (or at the deadline with what it has), 2 when it cannot connect.
import wsProtocol from "@foxglove/ws-protocol";
import WebSocket from "ws";

import { channelParser } from "./decode.mjs";

const { FoxgloveClient } = wsProtocol;

const [port, subprotocol, seconds] = [process.argv[2], process.argv[3], Number(process.argv[4] ?? 20)];
const ws = new WebSocket(`ws://127.0.0.1:${port}`, [subprotocol]);
const client = new FoxgloveClient({ ws });
const channels = new Map();   // subscription id -> {topic, parse, row}
const rows = {};
let agreed = null;
let capabilities = [];
const times = [];

function finish(code) {
  const t = times.length ? { count: times.length, first: String(times[0]), last: String(times[times.length - 1]) }
    : { count: 0, first: null, last: null };
  console.log(JSON.stringify({ subprotocol: agreed, capabilities, time: t, channels: rows }));
  process.exit(code);
}

function done() {
  const all = Object.values(rows);
  return all.length > 0 && all.every((r) => r.decoded > 0) && (!capabilities.includes("time") || times.length >= 2);
}

ws.on("open", () => { agreed = ws.protocol; });
client.on("error", (err) => { console.error(String(err)); });
client.on("serverInfo", (info) => { capabilities = info.capabilities ?? []; });
client.on("time", ({ timestamp }) => { times.push(timestamp); if (done()) finish(0); });
ws.on("unexpected-response", (_req, res) => { console.error(`HTTP ${res.statusCode}`); finish(2); });
client.on("advertise", (advertised) => {
  for (const ch of advertised) {
    const row = { schemaName: ch.schemaName, encoding: ch.encoding, decoded: 0, error: null };
    rows[ch.topic] = row;
    let parse = null;
    try {
      const data = ch.schemaEncoding === "protobuf" ? Buffer.from(ch.schema, "base64")
        : new TextEncoder().encode(ch.schema);
      parse = channelParser(ch.encoding, ch.schemaName, ch.schemaEncoding ?? "", data);
    } catch (err) {
      row.error = `schema: ${err}`;
    }
    const id = client.subscribe(ch.id);
    channels.set(id, { topic: ch.topic, parse, row });
  }
});
client.on("message", ({ subscriptionId, data }) => {
  const c = channels.get(subscriptionId);
  if (!c || !c.parse) return;
  try {
    const msg = c.parse.deserialize(new Uint8Array(data.buffer, data.byteOffset, data.byteLength));
    if (msg === undefined || msg === null) throw new Error("decoded to nothing");
    c.row.decoded += 1;
  } catch (err) {
    c.row.error ??= `decode: ${err}`;
  }
  if (done()) finish(0);
});
setTimeout(() => finish(0), seconds * 1000);
