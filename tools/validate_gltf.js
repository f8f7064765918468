#!/usr/bin/env node
// Validates a .glb (or .gltf) file with the Khronos glTF-Validator (npm package `gltf-validator`,
// installed by `tools/install-deps.sh --test` under $HOME/.cache/lodstream-npm), as tests/test_writers.cpp
// does for the GLB writer (io/glb_writer.cpp).
//
// Usage: node tools/validate_gltf.js FILE.glb [FILE.glb ...]
// Prints the report's issues (numErrors, numWarnings, numInfos, numHints, messages, truncated) as JSON;
// with several files (3D Tiles: every tile in one process), one JSON object {file: issues} of them all.
// Exit status: 0 no errors, 1 errors, 2 bad usage or the file could not be read or validated,
// 77 the validator is not installed (the output then starts with "skipped:").
// The package is looked up in $LODSTREAM_NPM_PREFIX/node_modules (an npm --prefix), then in
// $HOME/.cache/lodstream-npm/node_modules.
'use strict';

const fs = require('fs');
const path = require('path');

const { findModule } = require('./npm_modules');

function loadValidator() {
  const module = findModule('gltf-validator');
  return module ? require(module) : null;
}

async function main() {
  if (process.argv.length < 3) {
    console.error('usage: node tools/validate_gltf.js FILE.glb [FILE.glb ...]');
    return 2;
  }
  const validator = loadValidator();
  if (!validator) {
    console.log('skipped: npm package gltf-validator not found (run tools/install-deps.sh --test, ' +
                'or set LODSTREAM_NPM_PREFIX)');
    return 77;
  }
  const files = process.argv.slice(2);
  const all = {};
  let errors = 0;
  for (const file of files) {
    const issues = await validate(validator, file);
    if (issues === null) return 2;
    all[file] = issues;
    errors += issues.numErrors;
  }
  console.log(JSON.stringify(files.length === 1 ? all[files[0]] : all, null, 2));
  return errors === 0 ? 0 : 1;
}

// The issues of one file, or null (after a message) when it cannot be read or validated.
async function validate(validator, file) {
  let bytes;
  try {
    bytes = new Uint8Array(fs.readFileSync(file));
  } catch (e) {
    console.error(`${file}: cannot read: ${e.message}`);
    return null;
  }
  let report;
  try {
    report = await validator.validateBytes(bytes, {uri: path.basename(file), maxIssues: 1000});
  } catch (e) {
    console.error(`${file}: cannot validate: ${e}`);
    return null;
  }
  return report.issues;
}

main().then((code) => { process.exitCode = code; });
