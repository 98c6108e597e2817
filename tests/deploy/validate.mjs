// Validates every object of rendered Kubernetes manifests (multi-document YAML files given as
// arguments) against the Kubernetes and KEDA JSON schemas shipped by kubernetes-models and
// @kubernetes-models/keda. Prints one line per file and "N passed, N failed"; exits 1 on any error.
import { readFileSync } from "node:fs";
import yaml from "js-yaml";

const modulePath = (apiVersion) => {
  if (apiVersion.startsWith("keda.sh/")) return `@kubernetes-models/keda/${apiVersion}`;
  return apiVersion.includes("/") ? `kubernetes-models/${apiVersion}` : `kubernetes-models/${apiVersion}`;
};

let passed = 0;
let failed = 0;
for (const file of process.argv.slice(2)) {
  const docs = yaml.loadAll(readFileSync(file, "utf8")).filter((d) => d);
  for (const doc of docs) {
    const what = `${file}: ${doc.kind}/${doc.metadata?.name}`;
    try {
      const module = await import(modulePath(doc.apiVersion));
      const Model = module[doc.kind];
      if (!Model) throw new Error(`no schema for ${doc.apiVersion} ${doc.kind}`);
      new Model(doc).validate();
      passed++;
    } catch (e) {
      failed++;
      console.log(`FAIL ${what}: ${e.message}`);
    }
  }
  console.log(`${file}: ${docs.length} objects checked`);
}
console.log(`${passed} passed, ${failed} failed`);
process.exit(failed === 0 ? 0 : 1);
