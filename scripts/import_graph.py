#!/usr/bin/env python3
"""The import graph of a crate's `src/`: which file uses which, and its cycles.

An edge A -> B means a `use` (or an inline `crate::`/`super::`/`self::` path) in A names an
item defined in B. Re-exports are followed to the file that defines the item, so `use
crate::gaps::Filler` points at `gaps/fillers.rs`, not at `gaps/mod.rs`. A `mod x;`
declaration is containment, not an import. `tests.rs` files and `#[cfg(test)] mod tests`
blocks are left out: a test reads its parent by design.

    python3 scripts/import_graph.py            # cycles and imports against the layers; exit 1 if any
    python3 scripts/import_graph.py --layers   # the edges between top-level modules
    python3 scripts/import_graph.py --edges    # every edge, one per line
    python3 scripts/import_graph.py --all      # a mod.rs's imports of its own files too

Standard library only. The parse is textual (comments and strings stripped first), which
is enough for this crate's style: one item per `pub use`, paths written in full.
"""
import os
import re
import sys
from collections import defaultdict

ROOT = sys.argv[sys.argv.index("--src") + 1] if "--src" in sys.argv else "src"

# The layers of docs/design.md §4, lowest first: a top-level module may import only those
# before it.
LAYERS = [
    "error", "dual", "io", "numeric", "names", "readback", "backend", "gaps",
    "siren", "checkpoint", "jacobian", "field",
    "data", "loss",
    "warp", "metrics",
    "train", "register", "prelude",
    "plot", "run", "experiments", "view", "export", "batch",
    "cli",
]


def strip(text):
    text = re.sub(r"/\*.*?\*/", "", text, flags=re.S)
    text = re.sub(r'r#"(.|\n)*?"#', '""', text)
    text = re.sub(r'"(\\.|[^"\\])*"', '""', text)
    text = re.sub(r"//[^\n]*", "", text)
    return text


def cut_test_blocks(text):
    """Drop `#[cfg(test)] mod x { ... }` blocks (balanced braces)."""
    out, i = [], 0
    for m in re.finditer(r"#\[cfg\(test\)\]\s*(pub\s+)?mod\s+\w+\s*\{", text):
        if m.start() < i:
            continue
        out.append(text[i : m.start()])
        depth, j = 1, m.end()
        while j < len(text) and depth:
            depth += {"{": 1, "}": -1}.get(text[j], 0)
            j += 1
        i = j
    out.append(text[i:])
    return "".join(out)


def module_files(root):
    """Module path (tuple) -> file, for every .rs under root."""
    mods = {}
    for dirpath, _, files in os.walk(root):
        for f in files:
            if not f.endswith(".rs"):
                continue
            path = os.path.join(dirpath, f)
            rel = os.path.relpath(path, root)[:-3].split(os.sep)
            if rel[-1] in ("mod", "lib", "main"):
                rel = rel[:-1]
            if rel and rel[0] == "bin":
                continue
            mods[tuple(rel)] = path
    return mods


def expand_use(tree):
    """`a::{b, c::{d, e}}` -> [a::b, a::c::d, a::c::e]."""
    tree = tree.replace(" ", "").replace("\n", "")
    m = re.match(r"^(.*?)\{(.*)\}$", tree)
    if not m:
        return [tree]
    prefix, inner = m.group(1), m.group(2)
    parts, depth, cur = [], 0, ""
    for ch in inner:
        if ch == "," and depth == 0:
            parts.append(cur)
            cur = ""
            continue
        depth += {"{": 1, "}": -1}.get(ch, 0)
        cur += ch
    parts.append(cur)
    out = []
    for p in parts:
        if p:
            out += [prefix + q for q in expand_use(p)]
    return out


def main():
    mods = module_files(ROOT)
    texts = {}
    for mod, path in mods.items():
        with open(path, encoding="utf-8") as fh:
            texts[mod] = cut_test_blocks(strip(fh.read()))

    def absolute(mod, path):
        segs = path.split("::")
        if segs[0] == "crate":
            base, segs = [], segs[1:]
        elif segs[0] in ("super", "self"):
            base = list(mod)
            while segs and segs[0] in ("super", "self"):
                if segs[0] == "super":
                    base = base[:-1]
                segs = segs[1:]
        elif tuple(mod) + (segs[0],) in mods:
            # A path from a child module (`use soap::SoapConfig` in `fused/mod.rs`).
            base = list(mod)
        else:
            return None
        return base + [s for s in segs if s]

    uses = {}  # mod -> list of absolute paths
    reexports = defaultdict(dict)  # mod -> name -> absolute path
    for mod, text in texts.items():
        paths = []
        for m in re.finditer(r"\b(pub(\([^)]*\))?\s+)?use\s+([^;]+);", text):
            for p in expand_use(m.group(3)):
                p = re.sub(r"::as\w+$", "", p.replace(" as ", "::as"))
                alias = None
                am = re.search(r"::as(\w+)$", p)
                if am:
                    alias = am.group(1)
                a = absolute(mod, p)
                if a is None:
                    continue
                if a[-1] == "self":
                    a = a[:-1]
                paths.append(a)
                if m.group(1) and a[-1] != "*":
                    reexports[mod][alias or a[-1]] = a
        for m in re.finditer(r"\b((?:crate|super|self)(?:::\w+)+)", text):
            if text[max(0, m.start() - 4) : m.start()].strip().endswith("use"):
                continue
            a = absolute(mod, m.group(1))
            if a:
                paths.append(a)
        uses[mod] = paths

    def resolve(path, depth=0):
        """The module file that defines what `path` names."""
        cur = ()
        for i, seg in enumerate(path):
            nxt = cur + (seg,)
            if nxt in mods:
                cur = nxt
                continue
            if seg in reexports.get(cur, {}) and depth < 10:
                return resolve(reexports[cur][seg], depth + 1)
            return cur
        return cur

    edges = defaultdict(set)
    for mod, paths in uses.items():
        for p in paths:
            target = resolve(p)
            if target != mod and target in mods and mods[target] != mods[mod]:
                if target == () or mods[target].endswith("tests.rs"):
                    continue
                edges[mod].add(target)
    for mod in list(edges):
        if mods[mod].endswith("tests.rs"):
            del edges[mod]

    name = lambda m: os.path.relpath(mods[m], ROOT)

    # A folder's `mod.rs` using its own parts (`mod learn; use learn::learn;`) is the
    # folder's face, Rust's idiom for one module in several files: those edges are counted
    # apart (`--all` keeps them), and a cycle is one that passes between siblings or folders.
    inward = {(a, b) for a, bs in edges.items() for b in bs if b[: len(a)] == a}
    if "--all" not in sys.argv:
        for a, b in inward:
            edges[a].discard(b)

    # Tarjan's strongly connected components.
    index, low, stack, on, comps, counter = {}, {}, [], set(), [], [0]

    def strong(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in edges.get(v, ()):
            if w not in index:
                strong(w)
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
                comps.append(comp)

    sys.setrecursionlimit(10000)
    for v in list(mods):
        if v not in index:
            strong(v)

    if "--edges" in sys.argv:
        for a in sorted(edges, key=name):
            for b in sorted(edges[a], key=name):
                print(f"{name(a)} -> {name(b)}")
    if "--layers" in sys.argv:
        top = defaultdict(set)
        for a, bs in edges.items():
            for b in bs:
                if a and b and a[0] != b[0]:
                    top[a[0]].add(b[0])
        for a in sorted(top):
            print(f"{a:>12} -> {', '.join(sorted(top[a]))}")
    upward = sorted(
        {(a[0], b[0]) for a, bs in edges.items() for b in bs
         if a and b and a[0] != b[0] and a[0] in LAYERS and b[0] in LAYERS
         and LAYERS.index(b[0]) > LAYERS.index(a[0])}
    )
    unlisted = sorted({m[0] for m in mods if m and m[0] not in LAYERS and m[0] != "lib"})
    n_edges = sum(len(b) for b in edges.values())
    print(
        f"{len(mods)} files, {n_edges} imports between files"
        + ("" if "--all" in sys.argv else f" (and {len(inward)} of a folder's mod.rs into its own files)")
        + f", {len(comps)} cycles"
    )
    for comp in comps:
        print("  cycle: " + " <-> ".join(sorted(name(m) for m in comp)))
    print(f"{len(upward)} imports against the layers of docs/design.md")
    for a, b in upward:
        print(f"  {a} imports {b}, a layer above it")
    for m in unlisted:
        print(f"  {m} is in no layer")
    return 1 if comps or upward or unlisted else 0


if __name__ == "__main__":
    sys.exit(main())
