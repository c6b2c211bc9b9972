"""Render the kustomize trees under deploy/kubernetes offline and check them.

kubectl is not packaged for Debian bookworm, so this renders the subset of
kustomize the manifests use, and refuses anything else:
  resources (files and kustomization folders), labels (pairs on every
  resource's metadata), patches from files targeting a kind and name: a
  JSON patch (RFC 6902, a YAML list of operations, applied with the
  `jsonpatch` package) or a strategic-merge `$patch: delete`.
Each rendered resource is validated against the Kubernetes OpenAPI schema of
the pinned version (`kubernetes-validate`, strict: unknown fields are
errors); kinds without a built-in schema (a ServiceMonitor) are checked by
hand. Then what ties the resources together is checked: selectors match the
pod labels, probes and ports exist, the maps volume is mounted read-only,
the grace period covers the preStop pause plus the configured drain, and
the configuration's paths lie on the maps volume.

  python scripts/k8s_render.py KUBERNETES_VERSION OUT_DIR TREE...

Writes each tree's ConfigMap `config.toml` to OUT_DIR/<tree>.config.toml,
for the service's own configuration loader to check (tests/deploy.rs).
Exits 1 with every problem found.
"""

import os
import sys
import tomllib

import jsonpatch
import kubernetes_validate
import yaml

KNOWN_KEYS = {"apiVersion", "kind", "resources", "patches", "labels"}
problems = []


def fail(where, message):
    problems.append(f"{where}: {message}")


def load_docs(path):
    with open(path) as f:
        return [d for d in yaml.safe_load_all(f) if d is not None]


def render(folder):
    """The resources of the kustomization in `folder`."""
    path = os.path.join(folder, "kustomization.yaml")
    (k,) = load_docs(path)
    unknown = set(k) - KNOWN_KEYS
    if unknown:
        fail(path, f"kustomize fields this renderer does not know: {sorted(unknown)}")
    out = []
    for r in k.get("resources", []):
        p = os.path.normpath(os.path.join(folder, r))
        out += render(p) if os.path.isdir(p) else load_docs(p)
    for label in k.get("labels", []):
        if label.get("includeSelectors") or label.get("includeTemplates"):
            fail(path, "labels: only metadata labels are rendered")
        for doc in out:
            doc.setdefault("metadata", {}).setdefault("labels", {}).update(label["pairs"])
    for patch in k.get("patches", []):
        target = patch.get("target", {})
        if set(patch) != {"path", "target"} or set(target) - {"kind", "name"}:
            fail(path, f"patches: only a file with a kind/name target: {patch}")
            continue
        (body,) = load_docs(os.path.join(folder, patch["path"]))
        hits = [
            d
            for d in out
            if d.get("kind") == target.get("kind")
            and d["metadata"].get("name") == target.get("name", d["metadata"].get("name"))
        ]
        if not hits:
            fail(path, f"patch {patch['path']} matches no resource")
        if isinstance(body, list):
            out = [jsonpatch.apply_patch(d, body) if any(d is h for h in hits) else d for d in out]
        elif body == {**body, "$patch": "delete"}:
            out = [d for d in out if not any(d is h for h in hits)]
        else:
            fail(path, f"patch {patch['path']}: a JSON patch list or $patch: delete")
    return out


def by_kind(docs, kind):
    return [d for d in docs if d.get("kind") == kind]


def matches(selector, labels):
    return bool(selector) and all(labels.get(k) == v for k, v in selector.items())


def check(tree, docs, version, out_dir):
    for d in docs:
        name = f"{tree}: {d.get('kind')}/{d.get('metadata', {}).get('name')}"
        try:
            kubernetes_validate.validate(d, version, strict=True)
        except kubernetes_validate.SchemaNotFoundError:
            if d.get("kind") != "ServiceMonitor":
                fail(name, f"no schema for {d.get('apiVersion')} {d.get('kind')} in Kubernetes {version}")
        except kubernetes_validate.ValidationError as e:
            fail(name, f"{'.'.join(str(p) for p in e.path)}: {e.message}")
    services = by_kind(docs, "Service")
    deployments = by_kind(docs, "Deployment")
    configs = by_kind(docs, "ConfigMap")
    if len(deployments) != 1 or len(services) != 1 or len(configs) != 1:
        fail(tree, "one Deployment, one Service and one ConfigMap expected")
        return
    (dep,), (svc,), (cm,) = deployments, services, configs
    pod = dep["spec"]["template"]
    pod_labels = pod["metadata"].get("labels", {})
    spec = pod["spec"]
    if not matches(dep["spec"]["selector"]["matchLabels"], pod_labels):
        fail(tree, "the Deployment's selector does not match its pods' labels")
    if not matches(svc["spec"]["selector"], pod_labels):
        fail(tree, "the Service's selector does not match the pods' labels")
    for pdb in by_kind(docs, "PodDisruptionBudget"):
        if not matches(pdb["spec"]["selector"]["matchLabels"], pod_labels):
            fail(tree, "the PodDisruptionBudget's selector does not match the pods")
    for hpa in by_kind(docs, "HorizontalPodAutoscaler"):
        ref = hpa["spec"]["scaleTargetRef"]
        if (ref["kind"], ref["name"]) != ("Deployment", dep["metadata"]["name"]):
            fail(tree, "the HorizontalPodAutoscaler does not scale the Deployment")
    for sm in by_kind(docs, "ServiceMonitor"):
        if not matches(sm["spec"]["selector"]["matchLabels"], svc["metadata"].get("labels", {})):
            fail(tree, "the ServiceMonitor's selector does not match the Service")
        names = {p.get("name") for p in svc["spec"]["ports"]}
        for e in sm["spec"]["endpoints"]:
            if e.get("port") not in names or e.get("path") != "/metrics":
                fail(tree, f"ServiceMonitor endpoint {e} is not the Service's /metrics")
    (c,) = [c for c in spec["containers"] if c["name"] == "bowloc"]
    ports = {p["name"]: p["containerPort"] for p in c.get("ports", [])}
    for p in svc["spec"]["ports"]:
        if p["targetPort"] not in ports:
            fail(tree, f"the Service targets port {p['targetPort']}, which the container lacks")
    for probe, path in [("readinessProbe", "/readyz"), ("livenessProbe", "/healthz")]:
        get = c.get(probe, {}).get("httpGet", {})
        if get.get("path") != path or get.get("port") not in ports:
            fail(tree, f"{probe} should GET {path} on a container port")
    for kind in ["requests", "limits"]:
        if not {"cpu", "memory"} <= set(c.get("resources", {}).get(kind, {})):
            fail(tree, f"the container needs cpu and memory {kind}")
    volumes = {v["name"]: v for v in spec.get("volumes", [])}
    mounts = {m["mountPath"]: m for m in c.get("volumeMounts", [])}
    for init in spec.get("initContainers", []):
        for m in init.get("volumeMounts", []):
            if m["name"] not in volumes:
                fail(tree, f"init container {init['name']} mounts unknown volume {m['name']}")
    for m in c.get("volumeMounts", []):
        if m["name"] not in volumes:
            fail(tree, f"the container mounts unknown volume {m['name']}")
        if not m.get("readOnly"):
            fail(tree, f"{m['mountPath']} is mounted read-write")
    config = tomllib.loads(cm["data"]["config.toml"])
    for key in ["vocabulary", "map"]:
        path = config["files"][key]
        if not any(path.startswith(p.rstrip("/") + "/") for p in mounts):
            fail(tree, f"files.{key} = {path} lies on no mounted volume")
    if config["server"]["listen"].rsplit(":", 1)[1] != str(ports.get("http")):
        fail(tree, "the configured listen port is not the container's http port")
    config_mount = next((m for m in c["volumeMounts"] if m["name"] == "config"), None)
    if config_mount is None or volumes.get("config", {}).get("configMap", {}).get("name") != cm["metadata"]["name"]:
        fail(tree, "the ConfigMap is not mounted")
    pre_stop = c.get("lifecycle", {}).get("preStop", {}).get("exec", {}).get("command", [])
    pause = float(pre_stop[1]) if pre_stop[:1] == ["sleep"] else 0.0
    drain = config["server"].get("drain_ms", 12000) / 1000
    grace = spec.get("terminationGracePeriodSeconds", 30)
    if grace < pause + drain:
        fail(tree, f"terminationGracePeriodSeconds {grace} < preStop {pause} s + drain {drain} s")
    with open(os.path.join(out_dir, f"{tree.replace('/', '-')}.config.toml"), "w") as f:
        f.write(cm["data"]["config.toml"])
    print(f"{tree}: {len(docs)} resources ({', '.join(d['kind'] for d in docs)}) valid against Kubernetes {version} (strict)")


def main():
    version, out_dir, trees = sys.argv[1], sys.argv[2], sys.argv[3:]
    for tree in trees:
        docs = render(tree)
        check(os.path.relpath(tree, "deploy/kubernetes"), docs, version, out_dir)
    for p in problems:
        print(p, file=sys.stderr)
    sys.exit(1 if problems else 0)


if __name__ == "__main__":
    main()
