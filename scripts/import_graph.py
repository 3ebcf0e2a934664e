"""Print the package-level import graph of the project's code and check that imports flow one way.

    .venv/bin/python scripts/import_graph.py [--modules] [--root REPO]

Every import in every ``.py`` file under the packages below (top-level, inside functions, relative
or through ``spectral_bench.``) is read with ``ast`` (nothing is imported). A node is a package
(``batch.verdict``); ``batch``'s own modules are split into its entry points (``batch:entries``,
the commands a user runs) and the library they stand on (``batch:base``). ``LAYERS`` declares the
order, highest first: a node may import any node of a lower layer, and one of its own layer only
where no circle results. Exit 0: no circle between nodes (nor between modules of different nodes)
and no upward import; 1: one or more, each printed with the files and lines that make it (a circle
between modules of one package is printed as a note); ``--modules`` also prints the module-level
edges.
"""
import argparse
import ast
import sys
from collections import defaultdict
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = "spectral_bench"

# highest first; nodes on one line are one layer (they may import each other only without a circle)
LAYERS = [
    ["addon"],                                               # Blender UI: above the runner
    ["batch:entries"],                                       # run.py, cli.py, compare_runs.py, make_references.py
    ["batch.jobs"],                                          # plans and runs jobs, the studies' too
    ["batch.studies"],                                       # sweep, stability: what the runner asks of them
    ["batch.report"],
    ["batch.verdict", "batch.backends"],
    ["batch:base"],                                          # exr, records, run_folder, previews, spectral_exr, scene inputs
    ["exporters"],
]
ENTRIES = {"run", "cli", "compare_runs", "make_references"}
SCANNED = ("addon", "batch", "exporters")


def set_root(root):
    global ROOT
    ROOT = Path(root).resolve()


def module_name(path):
    rel = path.relative_to(ROOT).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def node_of(module):
    """The graph node a module belongs to (None: outside the scanned packages)."""
    parts = module.split(".")
    if parts[0] not in SCANNED:
        return None
    if parts[0] == "batch":
        if len(parts) == 1:
            return "batch:base"
        if len(parts) == 2 and not (ROOT / "batch" / parts[1]).is_dir():
            return "batch:entries" if parts[1] in ENTRIES else "batch:base"
        return "batch." + parts[1]
    return parts[0]


def imported_modules(path, module):
    """(imported module, line) for every import of a project module in ``path``."""
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    is_package = path.name == "__init__.py"
    here = module.split(".") if is_package else module.split(".")[:-1]
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield from _project(alias.name, node.lineno)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = here[:len(here) - (node.level - 1)] if node.level > 1 else here
                if node.level - 1 > len(here):
                    continue  # above the repository: the extension's root package
                stem = ".".join(base + ([node.module] if node.module else []))
            else:
                stem = node.module or ""
            for alias in node.names:  # ``from .pkg import mod`` imports the module, else a name of pkg
                sub = f"{stem}.{alias.name}" if stem else alias.name
                yield from _project(sub if existing(sub) == sub else stem, node.lineno)


def _project(name, line):
    if name.startswith(PACKAGE + "."):
        name = name[len(PACKAGE) + 1:]
    if name.split(".")[0] in SCANNED:
        yield name, line


def existing(module):
    """The longest prefix of ``module`` that is a file or package of the repository."""
    parts = module.split(".")
    while parts:
        p = ROOT.joinpath(*parts)
        if p.with_suffix(".py").is_file() or (p / "__init__.py").is_file():
            return ".".join(parts)
        parts.pop()
    return None


def graph():
    """{(from node, to node): [(file, line, imported module), ...]} and the module-level edges."""
    edges, module_edges = defaultdict(list), set()
    for top in SCANNED:
        for path in sorted((ROOT / top).rglob("*.py")):
            if "templates" in path.parts:
                continue
            module = module_name(path)
            src = node_of(module)
            for target, line in imported_modules(path, module):
                target = existing(target)
                if target is None or target == module:
                    continue
                module_edges.add((module, target))
                dst = node_of(target)
                if dst and dst != src:
                    edges[(src, dst)].append((str(path.relative_to(ROOT)), line, target))
    return edges, module_edges


def layer_of(node):
    for i, layer in enumerate(LAYERS):
        if node in layer:
            return i
    raise SystemExit(f"import_graph: node {node!r} has no layer in LAYERS: declare it")


def circles(edges):
    """Strongly connected components with more than one node (Tarjan)."""
    succ = defaultdict(set)
    for a, b in edges:
        succ[a].add(b)
    index, low, stack, on, out = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in sorted(succ[v]):
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
                out.append(sorted(comp))

    for v in sorted({n for e in edges for n in e}):
        if v not in index:
            visit(v)
    return out


def module_circles(module_edges):
    return circles({e: None for e in module_edges})


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--modules", action="store_true", help="also print the module-level edges")
    ap.add_argument("--root", type=Path, default=ROOT, help="the repository to read (default: this one)")
    args = ap.parse_args(argv)
    set_root(args.root)
    edges, module_edges = graph()
    problems = []
    print("layers (highest first): " + " > ".join(" ".join(layer) for layer in LAYERS))
    print("package-level imports:")
    for (a, b), sites in sorted(edges.items()):
        la, lb = layer_of(a), layer_of(b)
        mark = "" if la < lb else ("  (same layer)" if la == lb else "  UPWARD")
        print(f"  {a} -> {b}  ({len(sites)} import{'s' * (len(sites) != 1)}){mark}")
        if la > lb:
            problems.append(f"upward import {a} -> {b}: " + "; ".join(f"{f}:{n} ({m})" for f, n, m in sites))
    for comp in circles(edges):
        inside = [f"{a} -> {b} at " + ", ".join(f"{f}:{n}" for f, n, _ in edges[(a, b)])
                  for (a, b) in sorted(edges) if a in comp and b in comp and layer_of(a) >= layer_of(b)]
        problems.append("package circle " + " <-> ".join(comp) + ": " + "; ".join(inside))
    notes = []
    for comp in module_circles(module_edges):
        if len({node_of(m) for m in comp}) > 1:  # across nodes: the package circle says it too
            problems.append("module circle " + " <-> ".join(comp))
        else:  # a package and its module that reads the package's table when called: not a layer matter
            notes.append("module circle inside one package (not a layer problem): " + " <-> ".join(comp))
    if args.modules:
        print("module-level imports:")
        for a, b in sorted(module_edges):
            print(f"  {a} -> {b}")
    for n in notes:
        print(n)
    if problems:
        print(f"{len(problems)} problem{'s' * (len(problems) != 1)}:")
        for p in problems:
            print("  " + p)
        return 1
    print("no circle, no upward import")
    return 0


if __name__ == "__main__":
    sys.exit(main())
