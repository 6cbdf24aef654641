"""Draw an action hierarchy with its per-subtask sizes (states/observations before → after abstraction).

Examples:
  pearl hierarchy config/pearl.domain.yaml --format png     # writes out/hierarchy-pearl.png
  pearl hierarchy config/pearl.domain.yaml --format dot > pearl.dot
  pearl hierarchy config/pearl.domain.yaml --policy out/policies/pearl --format png --out pearl.png

Sizes come from a saved plan: --policy DIR, else the default one of `pearl plan DOMAIN`
(out/policies/NAME) when it was planned for this domain; only without either is the
hierarchy planned here (--no-sizes draws the bare tree). PNG is drawn with matplotlib (no
graphviz needed), root on the left and one row per primitive, readable at screen size; its
full path is printed.
"""
from __future__ import annotations

import argparse
import sys
from typing import Any, Dict, List, Optional, Tuple

from pearl_pomdp.cli._progress import add_progress_arguments, show_progress

COMMAND = "hierarchy"
HELP = "draw the action hierarchy (dot or png) with per-subtask sizes"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("domain", help="factored domain .yaml")
    parser.add_argument("--hierarchy", help="action hierarchy .yaml (default: NAME.hierarchy.yaml beside the domain)")
    parser.add_argument("--format", choices=["dot", "png"], default="dot",
                        help="dot: Graphviz text (default, on stdout); png: a picture (default out/hierarchy-NAME.png)")
    parser.add_argument("--out", help="output file (dot: default stdout; png: default out/hierarchy-NAME.png)")
    parser.add_argument("--policy", help="saved plan (`pearl plan`) to read the sizes from "
                                         "(default: out/policies/NAME when it fits the domain)")
    parser.add_argument("--no-sizes", action="store_true", help="draw the tree only (no planning)")
    add_progress_arguments(parser)


def subtask_labels(hierarchy, report: Optional[dict]) -> Dict[str, str]:
    from pearl_pomdp.hierarchy.plan import horizon_text

    by_name = {r["name"]: r for r in (report or {}).get("subtasks", [])}
    labels = {}
    for name in hierarchy.subtasks:
        r = by_name.get(name)
        if r is None:
            labels[name] = name
        else:
            labels[name] = (f"{name}\nS {r['states_full']}→{r['states_abstract']}  Z {r['observations_full']}→"
                            f"{r['observations_abstract']}\n{r['solver']}, h={horizon_text(r)}, |Γ|={r['alpha_vectors']}")
    return labels


def to_dot(hierarchy, labels: Dict[str, str]) -> str:
    """Graphviz DOT text: subtasks as ellipses (with sizes), primitives as boxes (one node per occurrence)."""
    lines = [f'digraph "{hierarchy.name}" {{', "  rankdir=TB;", '  node [fontname="Helvetica"];']
    counter = [0]

    def q(text: str) -> str:
        return '"' + text.replace("\\", "\\\\").replace('"', '\\"').replace("\n", "\\n") + '"'

    def visit(name: str) -> str:
        node = f"t_{name}"
        lines.append(f"  {node} [shape=ellipse, label={q(labels[name])}];")
        for child in hierarchy.subtasks[name].children:
            if hierarchy.is_abstract(child):
                cid = visit(child)
            else:
                counter[0] += 1
                cid = f"p{counter[0]}_{child}"
                lines.append(f"  {cid} [shape=box, label={q(child)}];")
            lines.append(f"  {node} -> {cid};")
        return node

    visit(hierarchy.root)
    lines.append("}")
    return "\n".join(lines) + "\n"


def layout(hierarchy) -> Tuple[List[tuple], List[tuple]]:
    """Node positions ``(x, y, label-key, is_subtask)`` and edges of a left-to-right tree.

    x is the depth (root at 0); every primitive gets its own row (y = 0, -1, -2, … in
    depth-first order) and a subtask sits at the middle of its children's rows, so labels
    never overlap however many primitives a subtask has.
    """
    nodes: List[Any] = []   # (x, y, name, abstract) per node; a subtask's slot is filled after its children
    edges: List[tuple] = []
    next_row = [0.0]

    def visit(name: str, depth: int) -> int:
        ys = []
        my = len(nodes)
        nodes.append(None)
        for child in hierarchy.subtasks[name].children:
            if hierarchy.is_abstract(child):
                ci = visit(child, depth + 1)
            else:
                ci = len(nodes)
                nodes.append((float(depth + 1), next_row[0], child, False))
                next_row[0] -= 1.0
            edges.append((my, ci))
            ys.append(nodes[ci][1])
        nodes[my] = (float(depth), (max(ys) + min(ys)) / 2 if ys else next_row[0], name, True)
        return my

    visit(hierarchy.root, 0)
    return nodes, edges


#: Inches between two depth columns and between two primitive rows of the PNG.
COLUMN_INCHES = 2.7
ROW_INCHES = 0.42


def to_png(hierarchy, labels: Dict[str, str], out: str) -> None:
    """Draw the tree left to right (root left, primitives right, one row each) into ``out``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    nodes, edges = layout(hierarchy)
    columns = int(max(n[0] for n in nodes)) + 1
    rows = int(-min(n[1] for n in nodes)) + 1
    fig, ax = plt.subplots(figsize=(COLUMN_INCHES * columns + 0.6, ROW_INCHES * rows + 0.9))
    half = 0.5  # half a column: where an elbow edge turns
    for i, j in edges:
        (x0, y0), (x1, y1) = nodes[i][:2], nodes[j][:2]
        ax.plot([x0, x0 + half, x0 + half, x1], [y0, y0, y1, y1], color="0.55", lw=1.0, zorder=1)
    for x, y, key, is_sub in nodes:
        if is_sub:
            ax.text(x, y, labels[key], ha="center", va="center", fontsize=9, zorder=2, linespacing=1.25,
                    bbox=dict(boxstyle="round,pad=0.35", fc="#dbe9f6", ec="0.3"))
        else:
            ax.text(x - 0.05, y, key, ha="left", va="center", fontsize=10, zorder=2,
                    bbox=dict(boxstyle="square,pad=0.25", fc="white", ec="0.45"))
    ax.set_xlim(-0.55, columns - 0.05)
    ax.set_ylim(-rows + 0.4, 0.8)
    ax.axis("off")
    ax.set_title(f"{hierarchy.name}: action hierarchy (subtasks: states S and observations Z, full → abstract)",
                 fontsize=10)
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    plt.close(fig)


def _saved_report(args, domain, hierarchy) -> Optional[dict]:
    """The plan report of --policy, or of the default `pearl plan` policy when it fits.

    Raises:
        PolicyError: --policy was planned for another domain or hierarchy.
    """
    from pearl_pomdp.cli.plan import default_policy_dir
    from pearl_pomdp.errors import PolicyError
    from pearl_pomdp.hierarchy import load_hierarchical_policy

    if args.policy:
        report = load_hierarchical_policy(args.policy, domain).report
        if report.get("hierarchy") != hierarchy.name:
            raise PolicyError(f"{args.policy}: planned for hierarchy {report.get('hierarchy')!r}, "
                              f"not {hierarchy.name!r}")
        return report
    default = default_policy_dir(args.domain)
    if not (default / "hierarchy.json").is_file():
        return None
    try:
        report = load_hierarchical_policy(default, domain).report
    except PolicyError as err:  # planned for another version of the domain: plan again
        print(f"pearl hierarchy: not using {default} ({err}); planning", file=sys.stderr)
        return None
    return report if report.get("hierarchy") == hierarchy.name else None


def run(args: argparse.Namespace) -> int:
    from pathlib import Path

    from pearl_pomdp.cli.plan import domain_name, load_domain_any, load_hierarchy_for, warn_on_stderr

    domain = load_domain_any(args.domain)
    hierarchy = load_hierarchy_for(domain, args.domain, args.hierarchy, warn=warn_on_stderr("hierarchy"))
    report = None if args.no_sizes else _saved_report(args, domain, hierarchy)
    if report is None and not args.no_sizes:
        from pearl_pomdp.hierarchy import plan

        report = plan(domain, hierarchy, progress=show_progress(args)).report
    labels = subtask_labels(hierarchy, report)
    if args.format == "dot":
        text = to_dot(hierarchy, labels)
        if args.out:
            with open(args.out, "w") as fh:
                fh.write(text)
        else:
            sys.stdout.write(text)
        return 0
    out = Path(args.out) if args.out else Path("out") / f"hierarchy-{domain_name(Path(args.domain))}.png"
    out.parent.mkdir(parents=True, exist_ok=True)
    to_png(hierarchy, labels, str(out))
    print(out.resolve())
    return 0
