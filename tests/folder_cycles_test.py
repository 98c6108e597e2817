#!/usr/bin/env python3
"""No folder cycles: the folders under common/, services/ and clients/ depend on each other (through
#include) as a directed acyclic graph. Test files are left out (a test may use a higher layer, e.g.
a stage test runs the registry). Prints the cycle when there is one."""
import os
import re
import sys

root = sys.argv[1] if len(sys.argv) > 1 else os.path.join(os.path.dirname(__file__), "..")
include = re.compile(r'^#include "((?:common|services|clients)/[^/"]+)/')
edges = {}
for top in ("common", "services", "clients"):
    for dirpath, _, files in os.walk(os.path.join(root, top)):
        rel = os.path.relpath(dirpath, root).split(os.sep)
        folder = "/".join(rel[:2])
        for name in files:
            if not name.endswith((".h", ".cc")) or name.endswith(("_test.cc", "_benchmark.cc")):
                continue
            if "testing" in rel:
                continue
            with open(os.path.join(dirpath, name), encoding="utf-8") as f:
                for line in f:
                    m = include.match(line)
                    if m and m.group(1) != folder:
                        edges.setdefault(folder, set()).add(m.group(1))

state = {}
stack = []


def visit(node):
    state[node] = 1
    stack.append(node)
    for nxt in sorted(edges.get(node, ())):
        if state.get(nxt) == 1:
            cycle = stack[stack.index(nxt):] + [nxt]
            print("FAIL: folder cycle: " + " -> ".join(cycle))
            sys.exit(1)
        if nxt not in state:
            visit(nxt)
    stack.pop()
    state[node] = 2


for node in sorted(edges):
    if node not in state:
        visit(node)
print(f"{len(edges)} folders, {sum(len(v) for v in edges.values())} dependencies, no cycle")
print("1 passed, 0 failed")
