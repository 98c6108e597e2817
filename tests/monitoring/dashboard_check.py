#!/usr/bin/env python3
"""Checks the Grafana dashboard (deploy/monitoring/grafana/instascene.json) against a real
Prometheus that scrapes running InstaScene services (tests/monitoring_test.sh starts both).

Structure: unique panel ids, panels inside the 24-column grid without overlapping, every query on
the dashboard's `datasource` variable, every metric it names exported by the scraped services.
Queries: Grafana's variables substituted ($__rate_interval -> 1m, $stage -> .*), every panel's
every query must evaluate in Prometheus, and return data unless its panel is listed as allowed
empty (ALLOWED_EMPTY); the stage variable's label_values query must list stages.

Usage: dashboard_check.py DASHBOARD.json PROMETHEUS_URL TARGET_COUNT METRICS_FILE...
Prints "N passed, N failed"; exits 1 on any failure."""
import json
import re
import sys
import time
import urllib.parse
import urllib.request

# Panels whose series exist only in some states of the queue, with why.
ALLOWED_EMPTY = {
    "Oldest queued job by stage": "a stage has the series only while it has queued jobs",
}

dashboard_path, prometheus, target_count, *metric_files = sys.argv[1:]
dashboard = json.load(open(dashboard_path))
passed = failed = 0


def check(ok, what):
    global passed, failed
    if ok:
        passed += 1
    else:
        failed += 1
        print("FAIL", what, file=sys.stderr)


def query(expr):
    url = f"{prometheus}/api/v1/query?" + urllib.parse.urlencode({"query": expr})
    try:
        return json.load(urllib.request.urlopen(url, timeout=10))
    except urllib.error.HTTPError as e:  # 400: a query Prometheus cannot parse
        return json.load(e)


# Metric names the services export: sample lines and the families' TYPE lines (a family with no
# series now, such as the oldest queued job's age of an empty queue, still declares its type).
exported = set()
for path in metric_files:
    for line in open(path):
        if line.startswith("# TYPE "):
            exported.add(line.split()[2])
        elif not line.startswith("#") and line.strip():
            exported.add(re.match(r"[a-zA-Z_:][a-zA-Z0-9_:]*", line).group(0))

panels = [p for p in dashboard["panels"] if p["type"] != "row"]
ids = [p["id"] for p in dashboard["panels"]]
check(len(ids) == len(set(ids)), f"panel ids repeat: {ids}")
cells = {}
for p in dashboard["panels"]:
    g = p["gridPos"]
    check(g["x"] >= 0 and g["x"] + g["w"] <= 24, f"{p['title']}: outside the 24 columns")
    mine = {(x, y) for x in range(g["x"], g["x"] + g["w"]) for y in range(g["y"], g["y"] + g["h"])}
    check(not (mine & cells.keys()), f"{p['title']} overlaps {[cells[c] for c in mine & cells.keys()][:1]}")
    cells.update({c: p["title"] for c in mine})

# Every target's scrapes: three or more in the last minute, so that rate() has samples.
deadline = time.time() + 60
while time.time() < deadline:
    r = query("count(count_over_time(up[1m]) >= 3)")
    if r.get("status") == "success" and r["data"]["result"] and \
            r["data"]["result"][0]["value"][1] == target_count:
        break
    time.sleep(0.5)
else:
    check(False, f"Prometheus did not scrape the {target_count} targets three times in 60 s")
r = query("min(up)")
check(r["data"]["result"] and r["data"]["result"][0]["value"][1] == "1", "a target is down")

for p in panels:
    check(p["datasource"]["uid"] == "${datasource}", f"{p['title']}: not on the datasource variable")
    check(len(p["targets"]) > 0, f"{p['title']}: no query")
    for t in p["targets"]:
        expr = t["expr"]
        check(t["datasource"]["uid"] == "${datasource}", f"{p['title']}: a query not on the variable")
        for name in re.findall(r"\binstascene_[a-z_]+", expr):
            base = re.sub(r"_(bucket|count|sum)$", "", name)
            check(name in exported or base in exported, f"{p['title']}: {name} is not exported")
        concrete = expr.replace("$__rate_interval", "1m").replace("$stage", ".*")
        check("$" not in concrete, f"{p['title']}: a variable left unsubstituted in {concrete}")
        r = query(concrete)
        ok = r.get("status") == "success"
        check(ok, f"{p['title']}: Prometheus refused {concrete}: {r.get('error')}")
        if ok and p["title"] not in ALLOWED_EMPTY:
            check(len(r["data"]["result"]) > 0, f"{p['title']}: no data for {concrete}")

stage = [v for v in dashboard["templating"]["list"] if v["name"] == "stage"][0]
m = re.match(r"label_values\((\w+), (\w+)\)", stage["query"]["query"])
url = f"{prometheus}/api/v1/label/{m.group(2)}/values?" + urllib.parse.urlencode({"match[]": m.group(1)})
values = json.load(urllib.request.urlopen(url, timeout=10))["data"]
check({"decompose", "train", "segment"} <= set(values), f"the stage variable lists {values}")

print(f"{passed} passed, {failed} failed")
sys.exit(0 if failed == 0 else 1)
