#!/usr/bin/env python3
"""The layering rules CI keeps true (issue #26), over `src/` (binaries excluded):

1. No import circle between files: a file's `use crate::…` / `use super::…` / `crate::…`
   paths (outside `#[cfg(test)]` modules and comments) are its edges; every strongly
   connected component of more than one file is a circle. A parent `mod.rs` naming its
   children with `mod x;` is not an edge (only paths are), so `pub use child::X` re-exports
   are edges parent -> child, and a child importing `super::X` from its parent is one back.
2. No source file of `src/` (binaries included) over MAX_LINES lines, but those in OVER
   (each with its size when listed): a listed file may shrink, not grow, and a file that gets
   under the limit must leave the list. The list is empty since #26; keep it so.

    python3 .ci/layers.py [src]      exit 1 with the reasons when a rule breaks
"""
import os
import re
import sys

MAX_LINES = 800
# Files allowed over the limit, with their line counts when listed (none since #26).
OVER: dict = {}


def sources(root, bins=False):
    for dp, _, fs in os.walk(root):
        rel = os.path.relpath(dp, root)
        if not bins and (rel == "bin" or rel.startswith("bin" + os.sep)):
            continue
        for f in fs:
            if f.endswith(".rs"):
                yield os.path.join(dp, f)


def modpath(root, p):
    rel = os.path.relpath(p, root)[:-3].split(os.sep)
    if rel[-1] in ("mod", "lib"):
        rel = rel[:-1]
    return rel


def edges(root, files):
    bymod = {tuple(modpath(root, p)): p for p in files}

    def resolve(segs):
        for k in range(len(segs), 0, -1):
            if tuple(segs[:k]) in bymod:
                return bymod[tuple(segs[:k])]
        return None

    pat = re.compile(r"\b(crate|super)((?:::\w+)+)")
    out = {p: set() for p in files}
    for p in files:
        me = modpath(root, p)
        text = open(p, encoding="utf-8", errors="replace").read()
        cut = re.search(r"#\[cfg\(test\)\]\s*mod\s+\w+\s*\{", text)
        if cut:
            text = text[: cut.start()]
        text = re.sub(r"//[^\n]*", "", text)
        for m in pat.finditer(text):
            segs = m.group(2).split("::")[1:]
            if m.group(1) == "crate":
                base = []
            else:
                # `me` names a mod.rs by its folder: `super` is one module up either way.
                base = me[:-1]
                while segs and segs[0] == "super":
                    segs, base = segs[1:], base[:-1]
            t = resolve(base + segs)
            if t and t != p:
                out[p].add(t)
    return out


def circles(graph):
    index, low, on, stack, comps, n = {}, {}, set(), [], [], [0]
    sys.setrecursionlimit(100000)

    def visit(v):
        index[v] = low[v] = n[0]
        n[0] += 1
        stack.append(v)
        on.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                comps.append(sorted(comp))

    for v in graph:
        if v not in index:
            visit(v)
    return comps


def main():
    root = sys.argv[1] if len(sys.argv) > 1 else "src"
    files = sorted(sources(root))
    problems = []
    for c in circles(edges(root, files)):
        problems.append("import circle: " + " ".join(os.path.relpath(x, root) for x in c))
    for p in sorted(sources(root, bins=True)):
        rel = os.path.relpath(p, root)
        lines = sum(1 for _ in open(p, encoding="utf-8", errors="replace"))
        limit = OVER.get(rel, MAX_LINES)
        if lines > limit:
            problems.append(f"{rel}: {lines} lines (limit {limit})")
        elif rel in OVER and lines <= MAX_LINES:
            problems.append(f"{rel}: {lines} lines, under {MAX_LINES} now: take it off the OVER list")
    for rel in OVER:
        if not os.path.exists(os.path.join(root, rel)):
            problems.append(f"{rel}: listed in OVER but gone: take it off the list")
    for p in problems:
        print(p)
    print(f"{len(files)} files, {len(problems)} problems")
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
