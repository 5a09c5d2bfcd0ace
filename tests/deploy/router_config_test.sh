#!/usr/bin/env bash
# The router's shipped files agree with each other, without a cluster: nginx accepts
# deploy/nginx/recogd-router.conf with the example files of deploy/nginx/router/, and with the
# files the Kubernetes manifests give it (ConfigMaps recogd-router and recogd-placement; the
# resolver's kube-dns name, which does not resolve here, replaced by an address); the manifests
# mount what the configuration reads (folders, certificate keys, ports), name a shard for every
# StatefulSet pod, fully qualified, and give the shards the placement file the router reads.
# Usage: router_config_test.sh RECOG RECOGD PROJECT_DIR (the binaries are not used). Exits 77
# (skipped) without nginx.
recog=$1
recogd=$2
project=$3
# shellcheck source=router_test_lib.sh
source "$project/tests/deploy/router_test_lib.sh"
conf=$project/deploy/nginx/recogd-router.conf

make_router_certs
cp "$project"/deploy/nginx/router/*.map "$project"/deploy/nginx/router/*.conf "$tmp/router/"
write_router_conf "$(free_port)" "$(free_port)"

# The Kubernetes files, and what the manifests say about paths, names and ports.
if /usr/bin/python3 - "$project/deploy/k8s" "$tmp/router" "$conf" >"$tmp/k8s.log" 2>&1 <<'PYTHON'
import os, re, sys
import yaml
k8s, out, conf = sys.argv[1:4]
docs = {}
for name in ("recogd.yaml", "router.yaml"):
    with open(os.path.join(k8s, name)) as f:
        for d in yaml.safe_load_all(f):
            docs[(d["kind"], d["metadata"]["name"])] = d
files = dict(docs[("ConfigMap", "recogd-router")]["data"])
files.update(docs[("ConfigMap", "recogd-placement")]["data"])
assert re.search(r"^resolver kube-dns\.kube-system\.svc\.cluster\.local valid=", files["resolver.conf"], re.M), files
files["resolver.conf"] = files["resolver.conf"].replace("kube-dns.kube-system.svc.cluster.local", "127.0.0.1")
for name, text in files.items():
    with open(os.path.join(out, name), "w") as f:
        f.write(text)
# Every file the configuration includes is in the router's ConfigMaps, and nothing else.
text = open(conf).read()
included = set(re.findall(r"include /etc/recogd/router/([\w.]+);", text))
assert included == set(files), (included, set(files))
# The router pod mounts the folders the configuration reads, the Secret's keys are its files.
router = docs[("Deployment", "recogd-router")]["spec"]["template"]["spec"]
mounts = {m["mountPath"]: m["name"] for m in router["containers"][0]["volumeMounts"]}
volumes = {v["name"]: v for v in router["volumes"]}
assert mounts["/etc/nginx/conf.d/recogd-router.conf"] == "router-conf", mounts
sources = {s["configMap"]["name"] for s in volumes[mounts["/etc/recogd/router"]]["projected"]["sources"]}
assert sources == {"recogd-router", "recogd-placement"}, sources
assert "secret" in volumes[mounts["/etc/recogd/router-tls"]], volumes
assert {"/etc/recogd/router-tls/tls.crt", "/etc/recogd/router-tls/tls.key"} == \
    set(re.findall(r"ssl_certificate(?:_key)? (\S+);", text)), text
# Ports: the TLS listener behind the Service, the health-only listener behind the probe.
ports = {p["name"]: p["containerPort"] for p in router["containers"][0]["ports"]}
listens = re.findall(r"^\s*listen (\d+)( ssl)? http2;", text, re.M)
assert {(str(ports["grpc-tls"]), " ssl"), (str(ports["health"]), "")} == set(listens), (ports, listens)
assert router["containers"][0]["readinessProbe"]["grpc"]["port"] == ports["health"]
assert docs[("Service", "recogd-router")]["spec"]["ports"][0]["targetPort"] == ports["grpc-tls"]
# One shard per StatefulSet pod, at its fully qualified per-pod name (no search list in nginx).
shards = dict(l.rstrip(";").split() for l in files["shards.map"].splitlines() if l.strip())
replicas = docs[("StatefulSet", "recogd")]["spec"]["replicas"]
assert shards == {f"shard_{n}": f"recogd-{n}.recogd.default.svc.cluster.local:50051"
                  for n in range(replicas)}, shards
models = dict(l.rstrip(";").split() for l in files["models.map"].splitlines() if l.strip())
assert models == {"primary": shards["shard_0"],
                  "any": "recogd-models.default.svc.cluster.local:50051"}, models
assert docs[("Service", "recogd-models")]["spec"].get("publishNotReadyAddresses") is not True
# The shards read the placement table at the path the router's files are mounted from.
shard = docs[("StatefulSet", "recogd")]["spec"]["template"]["spec"]
assert "--placement-file /etc/recogd/router/placement.map" in shard["containers"][0]["args"][0]
shard_mounts = {m["mountPath"]: m["name"] for m in shard["containers"][0]["volumeMounts"]}
placement_volume = {v["name"]: v for v in shard["volumes"]}[shard_mounts["/etc/recogd/router"]]
assert placement_volume["configMap"]["name"] == "recogd-placement", placement_volume
PYTHON
then
  pass
else
  fail "the Kubernetes manifests agree with the router: $(cat "$tmp/k8s.log")"
fi
write_router_conf "$(free_port)" "$(free_port)"

report_and_exit
