// Validates glTF / GLB files with the Khronos glTF validator and prints one JSON line per
// file: {"file", "errors", "warnings", "infos", "messages": [first 20 errors/warnings]}.
// Used by tests/export.rs. Install once: `npm ci --prefix tools/gltf`.
import { readFile } from "node:fs/promises";
import validator from "gltf-validator";

let failed = false;
for (const file of process.argv.slice(2)) {
  const bytes = new Uint8Array(await readFile(file));
  const report = await validator.validateBytes(bytes, { maxIssues: 100 });
  const issues = report.issues;
  const messages = issues.messages
    .filter((m) => m.severity <= 1)
    .slice(0, 20)
    .map((m) => `${m.severity === 0 ? "error" : "warning"} ${m.code} ${m.pointer ?? ""}: ${m.message}`);
  console.log(JSON.stringify({
    file,
    errors: issues.numErrors,
    warnings: issues.numWarnings,
    infos: issues.numInfos,
    messages,
  }));
  failed ||= issues.numErrors > 0;
}
process.exit(failed ? 1 : 0);
