"""Checks of the Kubernetes manifests in deploy/k8s.

Every object the kustomization lists is validated, strictly (an unknown
field is an error), against the OpenAPI schemas of one Kubernetes version
that kubernetes-validate ships inside its package: no network, no cluster.
Then what a schema cannot see: that services select pods, mounts name
volumes, volumes name objects that exist, settings are ones the server reads,
ConfigMaps copy deploy/config byte for byte, and the certificate files the
zenoh configs name are mounted where they are read.

Each cross-reference check is a function returning its problems, run on the
real manifests (no problem) and on broken copies in memory (a problem), so
that every check is shown to bite.

    python -m pytest -q deploy/tests
"""

import copy
import re
from pathlib import Path

import kubernetes_validate
import pytest
import yaml

ROOT = Path(__file__).resolve().parents[2]
K8S = ROOT / "deploy" / "k8s"
# Every ConfigMap key is a copy of the file of that name here.
CONFIG_DIR = ROOT / "deploy" / "config"
SERVER_CONFIG = ROOT / "server" / "src" / "config.rs"

# The Kubernetes version whose schemas the manifests must pass.
KUBERNETES_VERSION = "1.33"

# Created by hand (deploy/k8s/README.md), never committed: name -> keys.
DOCUMENTED_SECRETS = {
    "meshless-tokens": {"tokens"},
    "meshless-tls": {"tls.crt", "tls.key", "ca.crt"},
    "zenohd-tls": {"tls.crt", "tls.key"},
}

WORKLOAD_KINDS = {"Deployment", "StatefulSet", "DaemonSet", "ReplicaSet", "Job"}


def kustomization():
    return yaml.safe_load((K8S / "kustomization.yaml").read_text())


def load_manifests():
    """[(file name, object)] for every object of every listed file."""
    out = []
    for name in kustomization().get("resources", []):
        for obj in yaml.safe_load_all((K8S / name).read_text()):
            if obj is not None:
                out.append((name, obj))
    return out


MANIFESTS = load_manifests()


def objects():
    return [copy.deepcopy(obj) for _, obj in MANIFESTS]


def find(objs, kind, name):
    for obj in objs:
        if obj["kind"] == kind and obj["metadata"]["name"] == name:
            return obj
    raise KeyError(f"{kind}/{name}")


def ident(obj):
    return f"{obj['kind']}/{obj['metadata']['name']}"


def workloads(objs):
    return [o for o in objs if o["kind"] in WORKLOAD_KINDS]


def pod_spec(workload):
    return workload["spec"]["template"]["spec"]


def pod_labels(workload):
    return workload["spec"]["template"]["metadata"].get("labels") or {}


def containers(workload):
    spec = pod_spec(workload)
    return spec.get("initContainers", []) + spec["containers"]


def selects(selector, labels):
    return bool(selector) and all(labels.get(k) == v for k, v in selector.items())


def server_container(objs):
    """The meshless-server container of the StatefulSet in objs."""
    return pod_spec(find(objs, "StatefulSet", "meshless"))["containers"][0]


def router_container(objs):
    """The zenohd container of its Deployment in objs."""
    return pod_spec(find(objs, "Deployment", "zenohd"))["containers"][0]


def put(mapping, key, value):
    """mapping[key] = value, as an expression (for the breakages below)."""
    mapping[key] = value


def set_env(container, name, value):
    for var in container["env"]:
        if var["name"] == name:
            var["value"] = value


def env_value(container, name):
    for var in container.get("env", []):
        if var["name"] == name:
            return var.get("value")
    raise KeyError(name)


def quantity_bytes(text):
    """A Kubernetes memory quantity ("8Gi", "512M", "1e3") in bytes."""
    units = {"Ki": 2**10, "Mi": 2**20, "Gi": 2**30, "Ti": 2**40, "Pi": 2**50,
             "k": 10**3, "M": 10**6, "G": 10**9, "T": 10**12, "P": 10**15}
    match = re.fullmatch(r"([0-9.eE+-]+?)(Ki|Mi|Gi|Ti|Pi|k|M|G|T|P)?", str(text))
    assert match, f"not a quantity: {text!r}"
    return float(match.group(1)) * units.get(match.group(2), 1)


# ---------------------------------------------------------------- schemas


def schema_problems(obj):
    try:
        version = kubernetes_validate.validate(obj, KUBERNETES_VERSION, strict=True)
    except kubernetes_validate.ValidationError as e:
        path = ".".join(str(p) for p in e.path)
        return [f"{ident(obj)}: {path}: {e.message}"]
    except kubernetes_validate.SchemaNotFoundError as e:
        # The command line only warns of this; here an object no schema
        # covers is an error.
        return [f"{ident(obj)}: {e.message}"]
    assert version == KUBERNETES_VERSION, f"validated against {version}"
    return []


@pytest.mark.parametrize(
    "obj", [obj for _, obj in MANIFESTS], ids=[f"{f}:{ident(o)}" for f, o in MANIFESTS]
)
def test_schema(obj):
    assert schema_problems(obj) == []


@pytest.mark.parametrize(
    "breakage",
    [
        lambda o: o["spec"]["template"]["spec"]["containers"][0].update(imagePullPolicyy="Always"),
        lambda o: o["metadata"].update(namespce="x"),
        lambda o: o["spec"].update(replicas="2"),
        lambda o: o["spec"]["template"]["spec"]["containers"][0]["env"].append(
            {"name": "MESHLESS_MAX_SESSIONS", "value": 64}
        ),
        lambda o: o["spec"]["template"]["spec"]["containers"][0]["ports"][0].update(
            containerPort="grpc"
        ),
    ],
    ids=["unknown-container-field", "unknown-metadata-field", "replicas-string",
         "env-value-integer", "port-string"],
)
def test_validator_rejects_a_broken_statefulset(breakage):
    obj = find(objects(), "StatefulSet", "meshless")
    breakage(obj)
    assert schema_problems(obj) != []


def test_validator_rejects_an_object_it_has_no_schema_for():
    obj = find(objects(), "Service", "meshless")
    obj["apiVersion"] = "v2"
    assert schema_problems(obj) != []


# ---------------------------------------------------------- kustomization


def test_kustomization_lists_every_manifest():
    listed = kustomization().get("resources", [])
    assert len(listed) == len(set(listed)), "a file listed twice"
    present = {p.name for p in K8S.iterdir() if p.suffix in (".yaml", ".yml")}
    present.discard("kustomization.yaml")
    assert set(listed) == present


def test_kustomization_is_namespace_agnostic_and_holds_no_secret():
    assert "namespace" not in kustomization()
    for obj in objects():
        assert "namespace" not in obj["metadata"], ident(obj)
        assert obj["kind"] != "Secret", f"{ident(obj)}: secret values are never committed"


def test_object_names_are_unique():
    names = [ident(o) for o in objects()]
    assert len(names) == len(set(names))


# ------------------------------------------------------- cross-references


def selector_problems(objs):
    problems = []
    for w in workloads(objs):
        match = w["spec"]["selector"]["matchLabels"]
        if not selects(match, pod_labels(w)):
            problems.append(f"{ident(w)}: selector does not select its own pods")
    for svc in (o for o in objs if o["kind"] == "Service"):
        selected = [w for w in workloads(objs) if selects(svc["spec"].get("selector"), pod_labels(w))]
        if not selected:
            problems.append(f"{ident(svc)}: selects no workload's pods")
        named_ports = {
            p["name"] for w in selected for c in containers(w) for p in c.get("ports", []) if "name" in p
        }
        numbered = {
            p["containerPort"] for w in selected for c in containers(w) for p in c.get("ports", [])
        }
        for port in svc["spec"]["ports"]:
            target = port.get("targetPort", port["port"])
            if target not in (named_ports if isinstance(target, str) else numbered):
                problems.append(f"{ident(svc)}: targetPort {target} is no container port")
    for pdb in (o for o in objs if o["kind"] == "PodDisruptionBudget"):
        match = pdb["spec"]["selector"]["matchLabels"]
        if not any(selects(match, pod_labels(w)) for w in workloads(objs)):
            problems.append(f"{ident(pdb)}: selects no workload's pods")
    return problems


def test_selectors():
    assert selector_problems(objects()) == []


def service_name_problems(objs):
    problems = []
    for sts in (o for o in objs if o["kind"] == "StatefulSet"):
        try:
            svc = find(objs, "Service", sts["spec"]["serviceName"])
        except KeyError:
            problems.append(f"{ident(sts)}: serviceName names no Service")
            continue
        if svc["spec"].get("clusterIP") != "None":
            problems.append(f"{ident(sts)}: {ident(svc)} is not headless")
        if not selects(svc["spec"].get("selector"), pod_labels(sts)):
            problems.append(f"{ident(sts)}: {ident(svc)} does not select its pods")
        if svc["spec"].get("publishNotReadyAddresses", False):
            problems.append(f"{ident(svc)}: routes to replicas not ready")
    return problems


def test_statefulset_service_name():
    assert service_name_problems(objects()) == []


def volume_problems(objs):
    problems = []
    configmaps = {o["metadata"]["name"]: o for o in objs if o["kind"] == "ConfigMap"}
    secrets = {o["metadata"]["name"]: set(o.get("data", {})) | set(o.get("stringData", {}))
               for o in objs if o["kind"] == "Secret"}
    secrets.update(DOCUMENTED_SECRETS)
    for w in workloads(objs):
        volumes = {v["name"]: v for v in pod_spec(w).get("volumes", [])}
        claims = {c["metadata"]["name"] for c in w["spec"].get("volumeClaimTemplates", [])}
        for c in containers(w):
            for mount in c.get("volumeMounts", []):
                if mount["name"] not in volumes and mount["name"] not in claims:
                    problems.append(f"{ident(w)}: mount {mount['name']} names no volume")
        for v in volumes.values():
            if "configMap" in v:
                name = v["configMap"]["name"]
                if name not in configmaps:
                    problems.append(f"{ident(w)}: volume {v['name']}: no ConfigMap {name}")
                    continue
                keys = set(configmaps[name].get("data", {}))
                items = v["configMap"].get("items", [])
            elif "secret" in v:
                name = v["secret"]["secretName"]
                if name not in secrets:
                    problems.append(f"{ident(w)}: volume {v['name']}: no Secret {name}")
                    continue
                keys = secrets[name]
                items = v["secret"].get("items", [])
            else:
                continue
            for item in items:
                if item["key"] not in keys:
                    problems.append(f"{ident(w)}: volume {v['name']}: {name} has no key {item['key']}")
    return problems


def test_volumes():
    assert volume_problems(objects()) == []


def mounted_sources(workload, container, objs=None):
    """{path: (kind, object name, key)} for the files a container sees
    through its secret and configMap volumes (with items: those paths;
    without: every key)."""
    objs = objects() if objs is None else objs
    volumes = {v["name"]: v for v in pod_spec(workload).get("volumes", [])}
    configmaps = {o["metadata"]["name"]: o for o in objs if o["kind"] == "ConfigMap"}
    files = {}
    for mount in container.get("volumeMounts", []):
        v = volumes.get(mount["name"], {})
        if "secret" in v:
            kind, source = "Secret", v["secret"]
            name = source["secretName"]
            keys = DOCUMENTED_SECRETS.get(name, ())
        elif "configMap" in v:
            kind, source = "ConfigMap", v["configMap"]
            name = source["name"]
            keys = configmaps.get(name, {}).get("data", {})
        else:
            continue
        items = source.get("items") or [{"key": k, "path": k} for k in keys]
        for item in items:
            files[f"{mount['mountPath'].rstrip('/')}/{item['path']}"] = (kind, name, item["key"])
    return files


def mounted_files(workload, container, objs=None):
    return set(mounted_sources(workload, container, objs))


def mounted_config(objs, workload, container, path):
    """The text of the ConfigMap key mounted at path, or None."""
    kind, name, key = mounted_sources(workload, container, objs).get(path, (None, None, None))
    if kind != "ConfigMap":
        return None
    try:
        return find(objs, "ConfigMap", name).get("data", {}).get(key)
    except KeyError:
        return None


def test_files_the_server_and_probes_read_are_mounted():
    sts = find(objects(), "StatefulSet", "meshless")
    server = pod_spec(sts)["containers"][0]
    files = mounted_files(sts, server)
    for name in ("MESHLESS_TOKENS_FILE", "MESHLESS_TLS_CERT", "MESHLESS_TLS_KEY"):
        assert env_value(server, name) in files, name
    for probe in ("readinessProbe", "livenessProbe", "startupProbe"):
        command = server[probe]["exec"]["command"]
        assert command[command.index("--tls-ca") + 1] in files, probe
    mounts = {m["mountPath"] for m in server["volumeMounts"]}
    assert env_value(server, "MESHLESS_CHECKPOINT_DIR") in mounts

    zenohd = find(objects(), "Deployment", "zenohd")
    router = pod_spec(zenohd)["containers"][0]
    assert router["command"][-1] in mounted_files(zenohd, router)


def config_copy_problems(objs):
    problems = []
    for cm in (o for o in objs if o["kind"] == "ConfigMap"):
        for key, text in cm.get("data", {}).items():
            source = CONFIG_DIR / key
            if not source.is_file():
                problems.append(f"{ident(cm)}: {key}: no deploy/config/{key}")
            elif text.encode() != source.read_bytes():
                problems.append(f"{ident(cm)}: {key} differs from deploy/config/{key}")
    return problems


def test_configmaps_are_the_repository_files_byte_for_byte():
    objs = objects()
    assert config_copy_problems(objs) == []
    copied = {(o["metadata"]["name"], k) for o in objs if o["kind"] == "ConfigMap" for k in o["data"]}
    assert copied == {("zenohd-config", "zenohd.json5"), ("meshless-zenoh", "zenoh-client.json5")}


def zenoh_link_problems(objs):
    """The servers dial the router Service over TLS, with a zenoh config
    that a mounted ConfigMap key holds."""
    problems = []
    sts = find(objs, "StatefulSet", "meshless")
    server = pod_spec(sts)["containers"][0]
    if env_value(server, "MESHLESS_ZENOH_MODE") != "client":
        problems.append("MESHLESS_ZENOH_MODE is not client")
    for endpoint in env_value(server, "MESHLESS_ZENOH_CONNECT").split(","):
        match = re.fullmatch(r"tls/([a-z0-9-]+):(\d+)", endpoint)
        if not match:
            problems.append(f"MESHLESS_ZENOH_CONNECT {endpoint}: not tls/SERVICE:PORT")
            continue
        try:
            svc = find(objs, "Service", match.group(1))
        except KeyError:
            problems.append(f"MESHLESS_ZENOH_CONNECT {endpoint}: no such Service")
            continue
        if int(match.group(2)) not in {p["port"] for p in svc["spec"]["ports"]}:
            problems.append(f"MESHLESS_ZENOH_CONNECT {endpoint}: {ident(svc)} has no such port")
    path = env_value(server, "MESHLESS_ZENOH_CONFIG")
    if mounted_config(objs, sts, server, path) is None:
        problems.append(f"MESHLESS_ZENOH_CONFIG {path}: no mounted ConfigMap key")
    return problems


def test_servers_connect_to_the_router_over_tls():
    assert zenoh_link_problems(objects()) == []


def json5_strings(text, key):
    """The quoted values of `key: "..."` in a JSON5 text, comment lines
    left out: enough for these files, no JSON5 parser."""
    code = "\n".join(l for l in text.splitlines() if not l.lstrip().startswith("//"))
    return re.findall(rf"""["']?\b{re.escape(key)}\b["']?\s*:\s*["']([^"']+)["']""", code)


def tls_file_problems(objs):
    """The certificate files the zenoh configs name are mounted where the
    config is read: the client's root CA in the servers, the router's
    certificate and key in the router."""
    problems = []
    wanted = [
        ("StatefulSet", "meshless", lambda c: env_value(c, "MESHLESS_ZENOH_CONFIG"),
         ["root_ca_certificate"]),
        ("Deployment", "zenohd", lambda c: c["command"][c["command"].index("-c") + 1],
         ["listen_certificate", "listen_private_key"]),
    ]
    for kind, name, config_path, keys in wanted:
        w = find(objs, kind, name)
        c = pod_spec(w)["containers"][0]
        text = mounted_config(objs, w, c, config_path(c))
        if text is None:
            problems.append(f"{kind}/{name}: its zenoh config is not mounted")
            continue
        files = mounted_files(w, c, objs)
        for key in keys:
            paths = json5_strings(text, key)
            if not paths:
                problems.append(f"{kind}/{name}: its zenoh config sets no {key}")
            for path in paths:
                if path not in files:
                    problems.append(f"{kind}/{name}: {key} {path} is not mounted")
    return problems


def test_zenoh_tls_files_are_mounted():
    assert tls_file_problems(objects()) == []


def test_json5_strings():
    text = '{\n  // listen_certificate: "no",\n  tls: { listen_certificate: "/a.crt", "root_ca_certificate": \'/b\' },\n}'
    assert json5_strings(text, "listen_certificate") == ["/a.crt"]
    assert json5_strings(text, "root_ca_certificate") == ["/b"]
    assert json5_strings(text, "listen_private_key") == []


def secret_mode_problems(objs):
    """A secret volume not readable by all needs the pod's fsGroup, or the
    non-root user cannot read it."""
    problems = []
    for w in workloads(objs):
        pod = pod_spec(w).get("securityContext", {})
        for v in pod_spec(w).get("volumes", []):
            mode = v.get("secret", {}).get("defaultMode", 0o644)
            if "secret" in v and not mode & 0o004 and pod.get("fsGroup") is None:
                problems.append(f"{ident(w)}: volume {v['name']}: mode {mode:o} and no fsGroup")
    return problems


def test_non_root_users_can_read_their_secrets():
    assert secret_mode_problems(objects()) == []


def probe_problems(objs):
    problems = []
    for w in workloads(objs):
        for c in containers(w):
            for kind in ("readinessProbe", "livenessProbe", "startupProbe"):
                probe = c.get(kind)
                if probe and "exec" in probe and probe["exec"]["command"][:2] != ["meshless", "health"]:
                    problems.append(f"{ident(w)}: {c['name']} {kind} is not `meshless health`")
                if probe and "grpc" in probe:
                    problems.append(f"{ident(w)}: {c['name']} {kind}: a grpc probe cannot speak TLS")
    return problems


def test_probes():
    objs = objects()
    assert probe_problems(objs) == []
    server = server_container(objs)
    for kind in ("readinessProbe", "livenessProbe", "startupProbe"):
        assert "exec" in server[kind], kind
    startup = server["startupProbe"]
    assert startup["periodSeconds"] * startup["failureThreshold"] >= 300


def server_env_names():
    return set(re.findall(r'\benv\s*=\s*"([A-Z0-9_]+)"', SERVER_CONFIG.read_text()))


def env_problems(objs, known):
    problems = []
    for w in workloads(objs):
        for c in containers(w):
            for var in c.get("env", []):
                if var["name"].startswith("MESHLESS_") and var["name"] not in known:
                    problems.append(f"{ident(w)}: {var['name']} is not in server/src/config.rs")
    return problems


def test_env_names_are_server_settings():
    assert env_problems(objects(), server_env_names()) == []


def test_service_links_stay_out_of_the_server_settings():
    # Service `meshless` would inject MESHLESS_SERVICE_HOST, MESHLESS_PORT...
    assert pod_spec(find(objects(), "StatefulSet", "meshless"))["enableServiceLinks"] is False


def memory_problems(objs):
    problems = []
    for w in workloads(objs):
        for c in containers(w):
            names = {v["name"] for v in c.get("env", [])}
            if "MESHLESS_MEMORY_BUDGET_MB" not in names:
                continue
            budget = int(env_value(c, "MESHLESS_MEMORY_BUDGET_MB")) * 2**20
            limit = c.get("resources", {}).get("limits", {}).get("memory")
            if limit is None or quantity_bytes(limit) <= budget:
                problems.append(f"{ident(w)}: memory limit {limit} not above the budget")
    return problems


def test_memory_limit_is_above_the_server_budget():
    objs = objects()
    assert memory_problems(objs) == []
    server = server_container(objs)
    assert "MESHLESS_MEMORY_BUDGET_MB" in {v["name"] for v in server["env"]}


def test_quantities():
    assert quantity_bytes("8Gi") == 8 * 2**30
    assert quantity_bytes("512Mi") == 512 * 2**20
    assert quantity_bytes("6G") == 6 * 10**9
    assert quantity_bytes("1024") == 1024


def test_containers_run_locked_down():
    for w in workloads(objects()):
        pod = pod_spec(w).get("securityContext", {})
        assert pod.get("runAsNonRoot") is True, ident(w)
        assert pod.get("runAsUser") == 10001, ident(w)
        for c in containers(w):
            sc = c.get("securityContext", {})
            assert sc.get("allowPrivilegeEscalation") is False, ident(w)
            assert sc.get("readOnlyRootFilesystem") is True, ident(w)
            assert sc.get("capabilities", {}).get("drop") == ["ALL"], ident(w)
            assert {"requests", "limits"} <= set(c.get("resources", {})), ident(w)


def test_no_disruption_budget_for_a_single_replica():
    # minAvailable 1 on one replica would block node drains forever.
    objs = objects()
    for pdb in (o for o in objs if o["kind"] == "PodDisruptionBudget"):
        for w in workloads(objs):
            if selects(pdb["spec"]["selector"]["matchLabels"], pod_labels(w)):
                assert w["spec"].get("replicas", 1) > 1, f"{ident(pdb)} on {ident(w)}"


# ------------------------------------------------------- every check bites


def known_env_problems(objs):
    return env_problems(objs, server_env_names())


def renamed_key(objs, configmap, old, new):
    data = find(objs, "ConfigMap", configmap)["data"]
    data[new] = data.pop(old)


def edited_key(objs, configmap, key, old, new):
    data = find(objs, "ConfigMap", configmap)["data"]
    data[key] = data[key].replace(old, new)


# (check, breakage): each breakage, applied to its own copy of the
# manifests, must make its check report a problem.
BREAKAGES = {
    "selector-names-no-pods": (selector_problems, lambda o: put(
        find(o, "Service", "meshless")["spec"], "selector", {"app.kubernetes.io/name": "meshles"})),
    "target-port-no-container-port": (selector_problems, lambda o: put(
        find(o, "Service", "zenohd")["spec"]["ports"][0], "targetPort", "zenohd")),
    "pods-not-selected-by-own-workload": (selector_problems, lambda o: put(
        find(o, "StatefulSet", "meshless")["spec"]["template"]["metadata"], "labels", {"app": "x"})),
    "service-name-not-headless": (service_name_problems, lambda o: put(
        find(o, "StatefulSet", "meshless")["spec"], "serviceName", "meshless")),
    "mount-names-no-volume": (volume_problems, lambda o: put(
        server_container(o)["volumeMounts"][0], "name", "token")),
    "secret-not-documented": (volume_problems, lambda o: put(
        pod_spec(find(o, "StatefulSet", "meshless"))["volumes"][1]["secret"], "secretName",
        "meshless-certs")),
    "secret-key-missing": (volume_problems, lambda o: put(
        pod_spec(find(o, "StatefulSet", "meshless"))["volumes"][1]["secret"]["items"][2], "key",
        "ca.pem")),
    "configmap-missing": (volume_problems, lambda o: put(
        pod_spec(find(o, "Deployment", "zenohd"))["volumes"][0]["configMap"], "name", "zenohd")),
    "router-secret-not-documented": (volume_problems, lambda o: put(
        pod_spec(find(o, "Deployment", "zenohd"))["volumes"][1]["secret"], "secretName",
        "zenoh-tls")),
    "configmap-copy-edited": (config_copy_problems, lambda o: edited_key(
        o, "meshless-zenoh", "zenoh-client.json5", "ca.crt", "ca.pem")),
    "configmap-copy-one-byte-longer": (config_copy_problems, lambda o: edited_key(
        o, "zenohd-config", "zenohd.json5", "}\n", "}\n\n")),
    "configmap-key-no-config-file": (config_copy_problems, lambda o: renamed_key(
        o, "zenohd-config", "zenohd.json5", "router.json5")),
    "zenoh-over-tcp": (zenoh_link_problems, lambda o: set_env(
        server_container(o), "MESHLESS_ZENOH_CONNECT", "tcp/zenohd:7447")),
    "zenoh-to-no-service": (zenoh_link_problems, lambda o: set_env(
        server_container(o), "MESHLESS_ZENOH_CONNECT", "tls/zenoh:7447")),
    "zenoh-config-not-mounted": (zenoh_link_problems, lambda o: set_env(
        server_container(o), "MESHLESS_ZENOH_CONFIG", "/etc/meshless/zenoh-client.json5")),
    "zenoh-config-key-renamed": (zenoh_link_problems, lambda o: renamed_key(
        o, "meshless-zenoh", "zenoh-client.json5", "zenoh.json5")),
    "root-ca-not-mounted": (tls_file_problems, lambda o: edited_key(
        o, "meshless-zenoh", "zenoh-client.json5", "/tls/ca.crt", "/tls/ca.pem")),
    "root-ca-not-set": (tls_file_problems, lambda o: edited_key(
        o, "meshless-zenoh", "zenoh-client.json5", "root_ca_certificate", "root_ca")),
    "router-certificate-mounted-elsewhere": (tls_file_problems, lambda o: put(
        router_container(o)["volumeMounts"][1], "mountPath", "/etc/zenohd/certs")),
    "router-certificate-file-renamed": (tls_file_problems, lambda o: put(
        pod_spec(find(o, "Deployment", "zenohd"))["volumes"][1]["secret"]["items"][1], "path",
        "tls.pem")),
    "secret-unreadable-without-fsgroup": (secret_mode_problems, lambda o: pod_spec(
        find(o, "Deployment", "zenohd"))["securityContext"].pop("fsGroup")),
    "probe-not-meshless-health": (probe_problems, lambda o: put(
        server_container(o)["livenessProbe"]["exec"], "command", ["meshless", "ls"])),
    "grpc-probe": (probe_problems, lambda o: put(
        server_container(o), "readinessProbe", {"grpc": {"port": 50051}})),
    "env-not-a-server-setting": (known_env_problems, lambda o: server_container(o)["env"].append(
        {"name": "MESHLESS_GRPC_ADRESS", "value": "0.0.0.0:50051"})),
    "memory-limit-below-budget": (memory_problems, lambda o: put(
        server_container(o)["resources"]["limits"], "memory", "6Gi")),
}


@pytest.mark.parametrize("check, breakage", BREAKAGES.values(), ids=BREAKAGES.keys())
def test_every_check_bites(check, breakage):
    objs = objects()
    assert check(objs) == [], "the real manifests pass"
    breakage(objs)
    assert check(objs) != []
