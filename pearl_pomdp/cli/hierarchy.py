"""Draw an action hierarchy with its per-subtask sizes (states/observations before → after abstraction).

Examples:
  pearl hierarchy config/pearl.domain.yaml --format dot > pearl.dot
  pearl hierarchy config/pearl.domain.yaml --policy policies/pearl --format png --out pearl.png

Sizes come from a saved plan (--policy DIR); without it the hierarchy is planned first
(--no-sizes draws the bare tree). PNG is drawn with matplotlib (no graphviz needed).
"""
from __future__ import annotations

import argparse
import sys
from typing import Dict, List, Optional, Tuple

from pearl_pomdp.cli._progress import add_progress_arguments, show_progress

COMMAND = "hierarchy"
HELP = "draw the action hierarchy (dot or png) with per-subtask sizes"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("domain", help="factored domain .yaml")
    parser.add_argument("--hierarchy", help="action hierarchy .yaml (default: NAME.hierarchy.yaml beside the domain)")
    parser.add_argument("--format", choices=["dot", "png"], default="dot")
    parser.add_argument("--out", help="output file (dot: default stdout; png: default hierarchy.png)")
    parser.add_argument("--policy", help="saved plan (pearl plan --out DIR) to read the sizes from")
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
    """Node positions (x, y, label-key, is_subtask) and edges for a simple top-down tree drawing."""
    nodes, edges = [], []
    next_x = [0.0]

    def visit(name: str, depth: int) -> int:
        xs = []
        my = len(nodes)
        nodes.append(None)
        for child in hierarchy.subtasks[name].children:
            if hierarchy.is_abstract(child):
                ci = visit(child, depth + 1)
            else:
                ci = len(nodes)
                nodes.append((next_x[0], -(depth + 1), child, False))
                next_x[0] += 1.0
            edges.append((my, ci))
            xs.append(nodes[ci][0])
        nodes[my] = (sum(xs) / len(xs), -depth, name, True)
        return my

    visit(hierarchy.root, 0)
    return nodes, edges


def to_png(hierarchy, labels: Dict[str, str], out: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    nodes, edges = layout(hierarchy)
    width = max(6.0, 1.3 * sum(1 for n in nodes if not n[3]))
    depth = -min(n[1] for n in nodes) + 1
    fig, ax = plt.subplots(figsize=(width, 1.6 * depth + 1))
    for i, j in edges:
        ax.plot([nodes[i][0], nodes[j][0]], [nodes[i][1], nodes[j][1]], color="0.5", zorder=1)
    for x, y, key, is_sub in nodes:
        text = labels[key] if is_sub else key
        ax.text(x, y, text, ha="center", va="center", fontsize=7 if is_sub else 6.5, zorder=2,
                rotation=0 if is_sub else 30,
                bbox=dict(boxstyle="round,pad=0.3" if is_sub else "square,pad=0.2",
                          fc="#dbe9f6" if is_sub else "white", ec="0.3"))
    ax.set_xlim(-1, max(n[0] for n in nodes) + 1)
    ax.set_ylim(-depth, 0.6)
    ax.axis("off")
    ax.set_title(f"{hierarchy.name}: action hierarchy")
    fig.tight_layout()
    fig.savefig(out, dpi=130)
    plt.close(fig)


def run(args: argparse.Namespace) -> int:
    from pearl_pomdp.cli.plan import load_domain_any, load_hierarchy_for

    domain = load_domain_any(args.domain)
    hierarchy = load_hierarchy_for(domain, args.domain, args.hierarchy)
    report = None
    if args.policy:
        from pearl_pomdp.hierarchy import load_hierarchical_policy

        report = load_hierarchical_policy(args.policy, domain).report
    elif not args.no_sizes:
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
    out = args.out or "hierarchy.png"
    to_png(hierarchy, labels, out)
    print(out)
    return 0
