// Independent check of a rosbag2 MCAP file written by `sea-hil export --ros2` with Foxglove's own TypeScript
// stack: the reference reader (npm @mcap/core, summary/index path and sequential path), the ros2msg parser
// (@foxglove/rosmsg, ros2 mode) and the CDR decoder (@foxglove/rosmsg2-serialization) that Foxglove's ROS panels use.
//
// usage: node check_ros2_bag.mjs FILE.mcap  -> one JSON object on stdout:
//   {profile, library, indexedMessages, streamMessages, errors: [..],
//    channels: {topic: {schema, schemaEncoding, messageEncoding, metadata: {..}, messages, undecodable,
//               firstErrors: [..], first, last, logTimeMin, logTimeMax}}}
// `first` / `last` are the channel's first and last decoded messages (typed arrays as lists, bigints as strings).
// Exit status 0 when the file could be read (the verdict is in the JSON), 2 on a read failure.
import { readFile } from "node:fs/promises";
import { McapIndexedReader, McapStreamReader } from "@mcap/core";
import { parse } from "@foxglove/rosmsg";
import { MessageReader } from "@foxglove/rosmsg2-serialization";
import { decompress as zstdDecompress } from "fzstd";

const decompressHandlers = {
  zstd: (buffer, decompressedSize) => zstdDecompress(buffer, new Uint8Array(Number(decompressedSize))),
};

function plain(v) {
  if (typeof v === "bigint") return v.toString();
  if (ArrayBuffer.isView(v)) return Array.from(v, plain);
  if (Array.isArray(v)) return v.map(plain);
  if (v && typeof v === "object") return Object.fromEntries(Object.entries(v).map(([k, x]) => [k, plain(x)]));
  if (typeof v === "number" && !Number.isFinite(v)) return String(v);
  return v;
}

async function main(path) {
  const bytes = new Uint8Array(await readFile(path));
  const readable = { size: async () => BigInt(bytes.length),
                     read: async (offset, length) => bytes.subarray(Number(offset), Number(offset + length)) };
  const reader = await McapIndexedReader.Initialize({ readable, decompressHandlers });
  const out = { profile: reader.header.profile, library: reader.header.library, channels: {}, errors: [],
                indexedMessages: 0, streamMessages: 0 };
  const readers = new Map();   // schema id -> MessageReader
  for (const [id, schema] of reader.schemasById) {
    try {
      const text = new TextDecoder("utf-8", { fatal: true }).decode(schema.data);
      readers.set(id, new MessageReader(parse(text, { ros2: true })));
    } catch (err) {
      out.errors.push(`schema ${schema.name}: ${err.message}`);
    }
  }
  for (const [, ch] of reader.channelsById) {
    const s = reader.schemasById.get(ch.schemaId);
    out.channels[ch.topic] = { schema: s?.name ?? "", schemaEncoding: s?.encoding ?? "",
      messageEncoding: ch.messageEncoding, metadata: Object.fromEntries(ch.metadata), messages: 0, undecodable: 0,
      firstErrors: [], first: null, last: null, logTimeMin: null, logTimeMax: null };
  }
  for await (const msg of reader.readMessages()) {
    out.indexedMessages += 1;
    const ch = reader.channelsById.get(msg.channelId);
    const c = out.channels[ch.topic];
    c.messages += 1;
    const t = msg.logTime;
    if (c.logTimeMin === null || t < c.logTimeMin) c.logTimeMin = t;
    if (c.logTimeMax === null || t > c.logTimeMax) c.logTimeMax = t;
    try {
      const r = readers.get(ch.schemaId);
      if (!r) throw new Error("no reader for the schema");
      const value = plain(r.readMessage(msg.data));
      if (c.first === null) c.first = value;
      c.last = value;
    } catch (err) {
      c.undecodable += 1;
      if (c.firstErrors.length < 3) c.firstErrors.push(err.message);
    }
  }
  const stream = new McapStreamReader({ decompressHandlers, validateCrcs: true });
  stream.append(bytes);
  for (let rec; (rec = stream.nextRecord()); ) if (rec.type === "Message") out.streamMessages += 1;
  if (!stream.done()) out.errors.push("stream reader did not reach the end of the file");
  for (const c of Object.values(out.channels)) {
    for (const k of ["logTimeMin", "logTimeMax"]) c[k] = c[k] === null ? null : c[k].toString();
  }
  return out;
}

main(process.argv[2]).then(
  (out) => { process.stdout.write(JSON.stringify(out) + "\n"); },
  (err) => { process.stderr.write(`check_ros2_bag: ${err.stack ?? err}\n`); process.exit(2); },
);
