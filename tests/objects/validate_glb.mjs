// Validates .glb files with the Khronos glTF validator (npm gltf-validator). Usage:
//   node validate_glb.mjs FILE...   prints one line per file and "N passed, N failed" last;
// a file fails on any error (warnings and infos are printed, not failures).
import { readFileSync } from 'node:fs';
import { createRequire } from 'node:module';
const require = createRequire(import.meta.url);
const validator = require('gltf-validator');

let passed = 0;
let failed = 0;
for (const file of process.argv.slice(2)) {
  const report = await validator.validateBytes(new Uint8Array(readFileSync(file)), {
    uri: file,
    maxIssues: 50,
  });
  const { numErrors, numWarnings, messages } = report.issues;
  const draco = (report.info && report.info.extensionsUsed) || [];
  if (numErrors === 0) passed++;
  else failed++;
  console.log(`${file}: ${numErrors} errors, ${numWarnings} warnings; extensions ${draco.join(',')}`);
  for (const m of messages.filter((m) => m.severity <= 1)) {
    console.log(`  ${m.severity === 0 ? 'error' : 'warning'} ${m.code} ${m.pointer || ''}: ${m.message}`);
  }
}
console.log(`${passed} passed, ${failed} failed`);
process.exit(failed === 0 && passed > 0 ? 0 : 1);
