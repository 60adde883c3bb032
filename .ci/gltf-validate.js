#!/usr/bin/env node
// Validates glTF / GLB files with the Khronos glTF validator (npm package
// `gltf-validator`, installed into .ci/node_modules by .ci/run or
// `npm install --prefix .ci`). Prints one JSON line per file:
//   {"file": ..., "errors": N, "warnings": N, "infos": N, "hints": N, "messages": [...]}
// where messages lists the first errors and warnings (code, pointer, message).
// Exit status: 0 when every file has no errors, 1 otherwise, 2 on usage problems.
'use strict';
const fs = require('fs');
const path = require('path');

let validator;
try {
  validator = require(path.join(__dirname, 'node_modules', 'gltf-validator'));
} catch (e) {
  process.stderr.write('gltf-validator is not installed: run `npm install --prefix .ci`\n');
  process.exit(2);
}

async function validate(file) {
  const bytes = new Uint8Array(fs.readFileSync(file));
  const report = await validator.validateBytes(bytes, {
    uri: path.basename(file),
    maxIssues: 1000,
    externalResourceFunction: (uri) =>
      new Promise((resolve, reject) => {
        fs.readFile(path.join(path.dirname(file), decodeURIComponent(uri)), (err, data) =>
          err ? reject(err.toString()) : resolve(new Uint8Array(data)));
      }),
  });
  const issues = report.issues;
  const messages = issues.messages
    .filter((m) => m.severity <= 1)
    .slice(0, 20)
    .map((m) => ({ severity: m.severity === 0 ? 'error' : 'warning', code: m.code, pointer: m.pointer, message: m.message }));
  return {
    file,
    errors: issues.numErrors,
    warnings: issues.numWarnings,
    infos: issues.numInfos,
    hints: issues.numHints,
    messages,
  };
}

(async () => {
  const files = process.argv.slice(2);
  if (files.length === 0) {
    process.stderr.write('usage: node .ci/gltf-validate.js FILE.glb|FILE.gltf...\n');
    process.exit(2);
  }
  let failed = false;
  for (const f of files) {
    try {
      const r = await validate(f);
      if (r.errors > 0) failed = true;
      process.stdout.write(JSON.stringify(r) + '\n');
    } catch (e) {
      failed = true;
      process.stdout.write(JSON.stringify({ file: f, errors: 1, warnings: 0, infos: 0, hints: 0, messages: [{ severity: 'error', code: 'CRASH', message: String(e) }] }) + '\n');
    }
  }
  process.exit(failed ? 1 : 0);
})();
