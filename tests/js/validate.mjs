// Validate glTF files with the Khronos glTF-Validator; prints one JSON report per file
// ({"path", "numErrors", "numWarnings", "messages": [...]}) and exits 1 when any has errors.
// Usage: node validate.mjs FILE.glb [...]
import { readFile } from "node:fs/promises";
import validator from "gltf-validator";

let failed = false;
for (const path of process.argv.slice(2)) {
  const bytes = new Uint8Array(await readFile(path));
  const report = await validator.validateBytes(bytes, { maxIssues: 200, format: path.endsWith(".gltf") ? "gltf" : "glb" });
  const issues = report.issues;
  const out = { path, numErrors: issues.numErrors, numWarnings: issues.numWarnings,
                numInfos: issues.numInfos, messages: issues.messages };
  console.log(JSON.stringify(out));
  if (issues.numErrors > 0) failed = true;
}
process.exit(failed ? 1 : 0);
