// Checks rendered manifests against the build and the Dockerfile: every container's command is a
// binary the build produced (in BIN_DIR) and an ENTRYPOINT of docker/Dockerfile, and every
// container port is the port its --listen argument binds (the port named "metrics": its --metrics
// argument, which the pod's prometheus.io/port annotation names too); every container checks
// tokens from the instascene-auth Secret, and one that reaches other services has its own token
// (the gateway: none at all, callers' tokens pass through; HTTP probes on its --listen port); every
// CronJob runs the CLI with flags its subcommand takes. Usage: node consistency.mjs BIN_DIR
// DOCKERFILE FILE.yaml... Prints "N passed, N failed"; exits 1 on any mismatch.
import { execFileSync } from "node:child_process";
import { existsSync, readFileSync } from "node:fs";
import { basename, join } from "node:path";
import yaml from "js-yaml";

const [binDir, dockerfile, ...files] = process.argv.slice(2);
const docker = readFileSync(dockerfile, "utf8");
let passed = 0;
let failed = 0;
const check = (ok, what) => {
  if (ok) passed++;
  else {
    failed++;
    console.log(`FAIL ${what}`);
  }
};
// A CronJob runs a command of the CLI (BIN_DIR/../clients/cli/instascene, the Dockerfile's `cli`
// target): its subcommand must take every flag the manifest gives it (its --help lists them).
const cli = join(binDir, "..", "clients", "cli", "instascene");
const checkCronJob = (file, doc) => {
  for (const c of doc.spec.jobTemplate.spec.template.spec.containers) {
    const what = `${file}: ${doc.metadata.name}/${c.name}`;
    const command = (c.command ?? [])[0] ?? "";
    check(basename(command) === "instascene" && existsSync(cli), `${what}: ${command} is not the CLI ${cli}`);
    check(docker.includes(`ENTRYPOINT ["${command}"]`), `${what}: no Dockerfile ENTRYPOINT ${command}`);
    const [sub, ...args] = c.args ?? [];
    let help = "";
    try {
      help = execFileSync(cli, [sub, "--help"], { encoding: "utf8" });
    } catch (e) {
      help = "";
    }
    check(help.length > 0, `${what}: \`instascene ${sub} --help\` failed`);
    for (const a of args.filter((x) => x.startsWith("--"))) {
      const flag = a.split("=")[0];
      const listed = new RegExp(`(^|[\\s,])${flag}(?![\\w-])`, "m").test(help);
      check(listed, `${what}: instascene ${sub} takes no ${flag}`);
    }
  }
};
for (const file of files) {
  for (const doc of yaml.loadAll(readFileSync(file, "utf8")).filter((d) => d)) {
    if (doc.kind === "CronJob") checkCronJob(file, doc);
    if (doc.kind !== "Deployment") continue;
    for (const c of doc.spec.template.spec.containers) {
      const what = `${file}: ${doc.metadata.name}/${c.name}`;
      const command = (c.command ?? [])[0] ?? "";
      check(existsSync(join(binDir, basename(command))), `${what}: ${command} is not in ${binDir}`);
      check(docker.includes(`ENTRYPOINT ["${command}"]`), `${what}: no Dockerfile ENTRYPOINT ${command}`);
      const flag = (name) => (c.args ?? []).map((a) => a.replace(new RegExp(`^--${name}=`), "")).find((a, i) =>
        (c.args[i].startsWith(`--${name}=`)) || (i > 0 && c.args[i - 1] === `--${name}`));
      const listen = flag("listen");
      const port = listen ? Number(listen.split(":").pop()) : NaN;
      const metrics = flag("metrics");
      const metricsPort = metrics ? Number(metrics.split(":").pop()) : NaN;
      for (const p of c.ports ?? []) {
        if (p.name === "metrics") {
          check(p.containerPort === metricsPort, `${what}: metrics port ${p.containerPort} but --metrics ${metrics}`);
          const annotated = doc.spec.template.metadata?.annotations?.["prometheus.io/port"];
          check(Number(annotated) === metricsPort, `${what}: prometheus.io/port ${annotated} but --metrics ${metrics}`);
        } else {
          check(p.containerPort === port, `${what}: containerPort ${p.containerPort} but --listen ${listen}`);
        }
      }
      if (command.endsWith("instascene-gateway")) {
        // The gateway holds no token (callers' tokens pass through) and answers HTTP probes.
        check(flag("auth-tokens") === undefined && flag("token-file") === undefined,
          `${what}: the gateway must not hold tokens`);
        for (const probe of [c.readinessProbe, c.livenessProbe])
          check(probe?.httpGet?.port === port && probe?.httpGet?.path === "/api/v1/health",
            `${what}: an HTTP probe is not /api/v1/health on port ${port}`);
        continue;
      }
      // Authentication: the token file (and this process's own token) come from the auth Secret.
      const authDir = (flag("auth-tokens") ?? "").replace(/\/[^/]*$/, "");
      const mount = (c.volumeMounts ?? []).find((m) => m.mountPath === authDir);
      const volume = (doc.spec.template.spec.volumes ?? []).find((v) => v.name === mount?.name);
      check(volume?.secret?.secretName === "instascene-auth",
        `${what}: --auth-tokens is not read from the instascene-auth Secret`);
      const reachesOthers = flag("scheduler") !== undefined || command.endsWith("instascene-scheduler");
      if (reachesOthers)
        check((flag("token-file") ?? "").startsWith(authDir + "/"),
          `${what}: reaches other services without a --token-file from the auth Secret`);
      for (const probe of [c.readinessProbe, c.livenessProbe])
        check(probe?.grpc?.port === port, `${what}: a gRPC probe is not on port ${port}`);
    }
  }
}
console.log(`${passed} passed, ${failed} failed`);
process.exit(failed === 0 ? 0 : 1);
