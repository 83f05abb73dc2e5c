// Read MCAP files with the official TypeScript library, @mcap/core (tests/test_runlog.py):
// its indexed reader (McapIndexedReader, summary and chunk index) and its streaming reader
// (McapStreamReader, record by record). Prints one JSON object: path -> {indexed, stream}, each
// {topics: {topic: messages}, epochs: [epoch field of each /epoch message]} or {error: "..."}.
//
//     NODE_PATH=<folder with node_modules> node tests/mcap_readers.js FILE...
"use strict";
const fs = require("fs");
const { McapIndexedReader, McapStreamReader } = require("@mcap/core");
const { FileHandleReadable } = require("@mcap/nodejs");

function tally(result, topic, data) {
  result.topics[topic] = (result.topics[topic] || 0) + 1;
  if (topic === "/epoch") {
    result.epochs.push(JSON.parse(new TextDecoder().decode(data)).epoch);
  }
}

async function indexed(path) {
  const handle = await fs.promises.open(path, "r");
  try {
    const reader = await McapIndexedReader.Initialize({ readable: new FileHandleReadable(handle) });
    const result = { topics: {}, epochs: [], chunks: reader.chunkIndexes.length };
    for await (const message of reader.readMessages()) {
      tally(result, reader.channelsById.get(message.channelId).topic, message.data);
    }
    return result;
  } finally {
    await handle.close();
  }
}

function stream(path) {
  const reader = new McapStreamReader();
  reader.append(fs.readFileSync(path));
  const channels = new Map();
  const result = { topics: {}, epochs: [], footer: false };
  for (let record; (record = reader.nextRecord()); ) {
    if (record.type === "Channel") {
      channels.set(record.id, record.topic);
    } else if (record.type === "Message") {
      tally(result, channels.get(record.channelId), record.data);
    } else if (record.type === "Footer") {
      result.footer = true;
    }
  }
  if (!reader.done()) {
    throw new Error(`stream ended without a footer (${reader.bytesRemaining()} bytes unparsed)`);
  }
  return result;
}

async function main() {
  const out = {};
  for (const path of process.argv.slice(2)) {
    out[path] = {};
    try {
      out[path].indexed = await indexed(path);
    } catch (err) {
      out[path].indexed = { error: String(err && err.message ? err.message : err) };
    }
    try {
      out[path].stream = stream(path);
    } catch (err) {
      out[path].stream = { error: String(err && err.message ? err.message : err) };
    }
  }
  process.stdout.write(JSON.stringify(out));
}

main().catch((err) => {
  process.stderr.write(String(err && err.stack ? err.stack : err) + "\n");
  process.exit(1);
});
