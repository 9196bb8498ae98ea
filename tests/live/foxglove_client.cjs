// A viewer that is not vstig-hw's: Foxglove's own WebSocket client (@foxglove/ws-protocol) over `ws`,
// decoding with Foxglove's ROS 2 decoders (@foxglove/rosmsg, @foxglove/rosmsg2-serialization) and JSON.
// Usage: node foxglove_client.cjs ws://127.0.0.1:PORT [SUBPROTOCOL...]
// Subscribes to every channel advertised; prints one JSON object per line on stdout:
//   {"event":"open","protocol":...}, {"event":"serverInfo",...}, {"event":"advertise","channels":[...]},
//   {"event":"message","topic":...,"logTime":"<ns>","data":{...decoded...}}, {"event":"error"|"close",...}
// Stops when stdin closes. With STALL=1 in its environment it stops reading once subscribed: a stuck viewer.
"use strict";
const { FoxgloveClient } = require("@foxglove/ws-protocol");
const WebSocket = require("ws");
const { parse } = require("@foxglove/rosmsg");
const { MessageReader } = require("@foxglove/rosmsg2-serialization");

const [url, ...offered] = process.argv.slice(2);
// What today's Foxglove app offers; foxglove-sdk servers accept only this name.
const protocols = offered.length ? offered : ["foxglove.sdk.v1"];
const out = (obj) => process.stdout.write(JSON.stringify(obj, (_k, v) => (typeof v === "bigint" ? v.toString() : v)) + "\n");

const ws = new WebSocket(url, protocols);
const client = new FoxgloveClient({ ws });
const bySubscription = new Map(); // subscription id -> {topic, decode}
const textDecoder = new TextDecoder();

function decoderFor(channel) {
  if (channel.encoding === "cdr" && channel.schemaEncoding === "ros2msg") {
    const reader = new MessageReader(parse(channel.schema, { ros2: true }));
    return (view) => reader.readMessage(new Uint8Array(view.buffer, view.byteOffset, view.byteLength));
  }
  if (channel.encoding === "json") {
    return (view) => JSON.parse(textDecoder.decode(view));
  }
  throw new Error(`no decoder for ${channel.topic}: ${channel.encoding}/${channel.schemaEncoding}`);
}

ws.on("upgrade", () => {});
ws.on("open", () => out({ event: "open", protocol: ws.protocol }));
ws.on("unexpected-response", (_req, res) => {
  out({ event: "error", status: res.statusCode });
  process.exit(3);
});
client.on("serverInfo", (info) => out({ event: "serverInfo", name: info.name, capabilities: info.capabilities }));
client.on("error", (error) => out({ event: "error", message: String(error && error.message ? error.message : error) }));
client.on("close", () => { out({ event: "close" }); process.exit(0); });
client.on("advertise", (channels) => {
  out({ event: "advertise", channels: channels.map((c) => ({ id: c.id, topic: c.topic, encoding: c.encoding,
    schemaName: c.schemaName, schemaEncoding: c.schemaEncoding, schema: c.schema })) });
  for (const channel of channels) {
    const decode = decoderFor(channel);
    bySubscription.set(client.subscribe(channel.id), { topic: channel.topic, decode });
  }
  if (process.env.STALL === "1") {
    ws._socket.pause(); // read nothing more: the server's queue for us fills up
    out({ event: "stalled" });
  }
});
client.on("message", ({ subscriptionId, timestamp, data }) => {
  const sub = bySubscription.get(subscriptionId);
  if (sub === undefined) return;
  out({ event: "message", topic: sub.topic, logTime: timestamp, data: sub.decode(data) });
});
process.stdin.on("end", () => { ws.close(); process.exit(0); });
process.stdin.resume();
