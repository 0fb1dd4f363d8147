// Independent check of a sea-hil MCAP file with the reference TypeScript reader (npm @mcap/core), zstd chunks
// through fzstd (the recorder's default compression), JSON Schema validation with ajv (draft 2020-12), and the
// protobuf channels decoded with protobufjs from the FileDescriptorSet in their schema record (as Foxglove does:
// Root.fromDescriptor, lookupType(schema name)).
//
// usage: node check_mcap.mjs FILE.mcap  -> prints one JSON object on stdout:
//   {ok, channels: {topic: {schema, schemaEncoding, messageEncoding, messages, invalid, undecodable,
//    nonMonotonic, firstErrors: [..], seqZero, logTimeMin, logTimeMax, publishEqualsLog, decoded}},
//    wellKnownSchemasMatch: {topic: bool}, chunks, summaryChunks, metadata: {name: {...}}, errors: [..]}
//   `decoded` (protobuf channels only): every message as decoded, in file order (present fields only, int64 as
//   numbers), for the caller to compare with its own reader.
// Exit status 0 when the file could be read (the verdict is in the JSON), 2 on a read failure.
import { readFile } from "node:fs/promises";
import { McapIndexedReader, McapStreamReader } from "@mcap/core";
import { decompress as zstdDecompress } from "fzstd";
import Ajv2020 from "ajv/dist/2020.js";
import * as foxglove from "@foxglove/schemas/jsonschema.js";
import protobuf from "protobufjs";
import descriptor from "protobufjs/ext/descriptor/index.js";

const decompressHandlers = {
  zstd: (buffer, decompressedSize) => zstdDecompress(buffer, new Uint8Array(Number(decompressedSize))),
};
const FOXGLOVE = { "foxglove.Log": foxglove.Log, "foxglove.JointStates": foxglove.JointStates };

function withoutDollarSchema(obj) {
  const { $schema, ...rest } = obj;
  return rest;
}

function sameJson(a, b) {
  const canon = (v) => (Array.isArray(v) ? v.map(canon) : v && typeof v === "object"
    ? Object.fromEntries(Object.keys(v).sort().map((k) => [k, canon(v[k])])) : v);
  return JSON.stringify(canon(a)) === JSON.stringify(canon(b));
}

async function main(path) {
  const bytes = new Uint8Array(await readFile(path));
  const out = { ok: true, channels: {}, wellKnownSchemasMatch: {}, chunks: 0, summaryChunks: null, metadata: {},
                errors: [] };
  const ajv = new Ajv2020({ strict: false, allErrors: false });
  const schemas = new Map();   // schema id -> {name, encoding, validate}
  const channels = new Map();  // channel id -> {topic, schemaId, messageEncoding}
  const decoder = new TextDecoder("utf-8", { fatal: true });

  // 1. sequential read of every record (what a crashed-file reader does too)
  const stream = new McapStreamReader({ decompressHandlers, validateCrcs: true, includeChunks: true });
  stream.append(bytes);
  for (let rec; (rec = stream.nextRecord()); ) {
    if (rec.type === "Chunk") {
      out.chunks += 1;
    } else if (rec.type === "Schema") {
      const entry = { name: rec.name, encoding: rec.encoding, validate: null, type: null };
      if (rec.encoding === "jsonschema") {
        const parsed = JSON.parse(decoder.decode(rec.data));
        entry.validate = ajv.compile(parsed);
        if (FOXGLOVE[rec.name]) {
          out.wellKnownSchemasMatch[rec.name] = sameJson(withoutDollarSchema(parsed), FOXGLOVE[rec.name]);
        }
      }
      if (rec.encoding === "protobuf") {
        try {
          entry.type = protobuf.Root.fromDescriptor(descriptor.FileDescriptorSet.decode(rec.data)).lookupType(rec.name);
        } catch (err) {
          out.errors.push(`protobuf schema ${rec.name}: ${err.message}`);
        }
      }
      schemas.set(rec.id, entry);
    } else if (rec.type === "Channel") {
      channels.set(rec.id, { topic: rec.topic, schemaId: rec.schemaId, messageEncoding: rec.messageEncoding });
      const s = schemas.get(rec.schemaId);
      out.channels[rec.topic] ??= { schema: s?.name ?? "", schemaEncoding: s?.encoding ?? "",
        messageEncoding: rec.messageEncoding, messages: 0, invalid: 0, undecodable: 0, nonMonotonic: 0,
        seqZero: 0, publishEqualsLog: 0, logTimeMin: null, logTimeMax: null, firstErrors: [], lastLog: null };
    } else if (rec.type === "Message") {
      const ch = channels.get(rec.channelId);
      if (!ch) { out.errors.push(`message on unknown channel ${rec.channelId}`); continue; }
      const c = out.channels[ch.topic];
      c.messages += 1;
      const t = rec.logTime;
      if (c.lastLog !== null && t < c.lastLog) c.nonMonotonic += 1;
      c.lastLog = t;
      if (c.logTimeMin === null || t < c.logTimeMin) c.logTimeMin = t;
      if (c.logTimeMax === null || t > c.logTimeMax) c.logTimeMax = t;
      if (rec.sequence === 0) c.seqZero += 1;
      if (rec.publishTime === rec.logTime) c.publishEqualsLog += 1;
      let value;
      const s = schemas.get(ch.schemaId);
      try {
        if (ch.messageEncoding === "protobuf") {
          if (!s?.type) throw new Error(`no protobuf type for schema ${s?.name}`);
          const type = s.type;
          value = type.toObject(type.decode(rec.data), { longs: Number });
          (c.decoded ??= []).push(value);
          continue;   // decoding with the file's own descriptor is the schema check
        }
        if (ch.messageEncoding !== "json") throw new Error(`message encoding ${ch.messageEncoding}`);
        value = JSON.parse(decoder.decode(rec.data));
      } catch (err) {
        c.undecodable += 1;
        if (c.firstErrors.length < 3) c.firstErrors.push(`decode: ${err.message}`);
        continue;
      }
      if (!s?.validate) { c.invalid += 1; continue; }
      if (!s.validate(value)) {
        c.invalid += 1;
        if (c.firstErrors.length < 3) c.firstErrors.push(ajv.errorsText(s.validate.errors));
      }
    } else if (rec.type === "Metadata") {
      out.metadata[rec.name] = Object.fromEntries(rec.metadata);
    }
  }
  if (!stream.done()) out.errors.push("stream reader did not reach the end of the file");

  // 2. the summary/index path (what Foxglove uses to seek)
  const readable = { size: async () => BigInt(bytes.length),
                     read: async (offset, length) => bytes.subarray(Number(offset), Number(offset + length)) };
  const indexed = await McapIndexedReader.Initialize({ readable, decompressHandlers });
  out.summaryChunks = indexed.chunkIndexes.length;
  let indexedCount = 0;
  for await (const _ of indexed.readMessages()) indexedCount += 1;
  out.indexedMessages = indexedCount;

  for (const c of Object.values(out.channels)) {
    for (const k of ["logTimeMin", "logTimeMax"]) c[k] = c[k] === null ? null : c[k].toString();
    delete c.lastLog;
    if (c.invalid || c.undecodable || c.nonMonotonic) out.ok = false;
  }
  if (out.errors.length || Object.values(out.wellKnownSchemasMatch).some((v) => !v)) out.ok = false;
  return out;
}

main(process.argv[2]).then(
  (out) => { process.stdout.write(JSON.stringify(out) + "\n"); },
  (err) => { process.stderr.write(`check_mcap: ${err.stack ?? err}\n`); process.exit(2); },
);
