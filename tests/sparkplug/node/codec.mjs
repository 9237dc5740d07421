// Eclipse Tahu's JavaScript codec (sparkplug-payload), an implementation independent of
// ours, as a line-oriented service for tests/sparkplug: one JSON request per stdin line,
// one JSON answer per stdout line, in order.
//   {"decode": "<hex>", "types": {"<alias>": "Double", ...}}
//                         -> {"ok": <the payload as sparkplug-payload decodes it>}
//      A data message names its metrics by alias only, without their datatype: as a
//      host does, "types" gives each alias the datatype its birth said, set in the
//      message before Tahu decodes it (Tahu reads a value by its datatype).
//   {"encode": <payload>} -> {"ok": "<hex>"}   (a payload as sparkplug-payload takes it)
// 64-bit numbers (Long) are written as JSON numbers; bytes as hex.
import { createInterface } from "node:readline";
import { createRequire } from "node:module";

const require = createRequire(import.meta.url);
const sparkplug = require("sparkplug-payload").get("spBv1.0");
const Long = require("long");
const Payload = require("sparkplug-payload/lib/sparkplugPayloadProto").org.eclipse.tahu.protobuf.Payload;
const TYPES = [
  "Unknown", "Int8", "Int16", "Int32", "Int64", "UInt8", "UInt16", "UInt32", "UInt64",
  "Float", "Double", "Boolean", "String", "DateTime", "Text",
];

function typed(bytes, types) {
  const raw = Payload.decode(bytes);
  for (const metric of raw.metrics) {
    const name = metric.alias == null ? undefined : types[metric.alias.toString()];
    if (!metric.datatype && name !== undefined) metric.datatype = TYPES.indexOf(name);
  }
  return Payload.encode(raw).finish();
}

function plain(value) {
  if (Long.isLong(value)) return value.toNumber();
  if (value instanceof Uint8Array) return Buffer.from(value).toString("hex");
  if (Array.isArray(value)) return value.map(plain);
  if (value !== null && typeof value === "object") {
    return Object.fromEntries(Object.entries(value).map(([k, v]) => [k, plain(v)]));
  }
  return value;
}

const lines = createInterface({ input: process.stdin });
for await (const line of lines) {
  let answer;
  try {
    const request = JSON.parse(line);
    if ("decode" in request) {
      const bytes = Buffer.from(request.decode, "hex");
      const payload = request.types ? typed(bytes, request.types) : bytes;
      answer = { ok: plain(sparkplug.decodePayload(payload)) };
    } else {
      answer = { ok: Buffer.from(sparkplug.encodePayload(request.encode)).toString("hex") };
    }
  } catch (error) {
    answer = { error: String(error) };
  }
  process.stdout.write(JSON.stringify(answer) + "\n");
}
