// Decodes Sparkplug B payloads with Eclipse Tahu's codec, an implementation independent of
// fcmaster's. Reads one hex payload per line on stdin (an empty line is an empty payload);
// prints one JSON object per line (64-bit integers as decimal strings, bytes as hex).
"use strict";
const readline = require("readline");
const Long = require("long");
const { decodePayload } = require("sparkplug-payload").get("spBv1.0");

function plain(value) {
  if (Long.isLong(value)) return value.toString();
  if (value instanceof Uint8Array) return Buffer.from(value).toString("hex");
  if (Array.isArray(value)) return value.map(plain);
  if (value !== null && typeof value === "object") {
    const out = {};
    for (const [key, item] of Object.entries(value)) out[key] = plain(item);
    return out;
  }
  if (typeof value === "number" && !Number.isFinite(value)) return String(value);
  return value;
}

const lines = readline.createInterface({ input: process.stdin });
lines.on("line", (line) => {
  try {
    const payload = decodePayload(Buffer.from(line.trim(), "hex"));
    console.log(JSON.stringify(plain(payload)));
  } catch (error) {
    console.log(JSON.stringify({ error: String(error) }));
  }
});
