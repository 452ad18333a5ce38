// Decode CBOR with roslibjs's own decoder (cbor-js with roslib's cborTypedArrayTags, what
// ROSLIB.Ros does with a binary frame) and print the result, every typed array shown as
// {typed: its class, values}: `node cbor_decode.js HEX`.
'use strict';

const path = require('path');
const { createRequire } = require('module');

const fromWeb = createRequire(path.join(__dirname, '..', '..', '..', 'web-interface',
  'package.json'));
const roslibRequire = createRequire(fromWeb.resolve('roslib'));
const CBOR = roslibRequire('cbor-js');
const typedArrayTagger = roslibRequire('./util/cborTypedArrayTags');

function shown(value) {
  if (ArrayBuffer.isView(value)) {
    return { typed: value.constructor.name, values: Array.from(value, Number) };
  }
  if (Array.isArray(value)) {
    return { typed: 'Array', values: value };
  }
  if (value !== null && typeof value === 'object') {
    return Object.fromEntries(Object.entries(value).map(([key, item]) => [key, shown(item)]));
  }
  return value;
}

const bytes = Buffer.from(process.argv[2], 'hex');
const buffer = bytes.buffer.slice(bytes.byteOffset, bytes.byteOffset + bytes.byteLength);
process.stdout.write(`${JSON.stringify(shown(CBOR.decode(buffer, typedArrayTagger)))}\n`);
