// Validate glTF/GLB files with the Khronos glTF-Validator (npm package gltf-validator).
// Usage: node gltf_validate.mjs NODE_MODULES FILE...; prints one JSON array of reports.
import { readFile } from "node:fs/promises";
import { createRequire } from "node:module";
import path from "node:path";

const [modules, ...files] = process.argv.slice(2);
const require = createRequire(path.join(path.resolve(modules), "index.js"));
const validator = require("gltf-validator");
const reports = [];
for (const file of files) {
  const bytes = new Uint8Array(await readFile(file));
  reports.push(
    await validator.validateBytes(bytes, {
      uri: path.basename(file),
      maxIssues: 0,
      writeTimestamp: false,
    }),
  );
}
process.stdout.write(JSON.stringify(reports));
