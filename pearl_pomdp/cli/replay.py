"""Replay a recorded bag through the belief tracker and hierarchical policy (one process,
simulated time) and compare the actions they publish with the /pearl/action recorded.

The bag's recorded inputs (/pearl/speech, /pearl/touchscreen, /pearl/laser, /pearl/reminder)
and /clock are published in file order, as the recorded bytes, into the real nodes; each
message is fed once the graph has reacted to the previous one, so the result does not
depend on the machine's speed. The domain and planned policy come from --domain / --policy,
else the bag's metadata.yaml custom_data (pearl.domain, pearl.policy), else what the policy node
published on /hierarchical_policy/settings; the tracker's step rules likewise from
pearl.tracker_params or /belief_tracker/settings (a plain `pearl record` of a launched graph
replays as it ran).

Output: text, or with --json one object with "actions" (list), "expected_actions" (as
recorded), "match" (bool), "messages", "messages_per_second" (replay loop only). Exit code
0 when the actions match, 1 when they do not, 2 on an unreadable bag.

With --explain, why the robot did what it did: per step the input that closed it (topic,
text, recognised symbol, recogniser confidence), the most probable value of each belief
feature after the update, and the EXECUTE trace of the answer with the value of each
choice and, beside it, the runner-up at that level with its value (`Act→DoNothing (19.10;
next Rest→GoHome 18.42)`: what the choice beat and by how much); where replay and recording differ, the first divergence with both traces (when
the bag recorded /pearl/decision). In --json these are "steps" and "divergence".

A person in the loop is replayed too: the recorded vetoes and commands are fed to the
policy, and the operator's level changes and yes/no answers (recorded as events on
/pearl/operator/events) are done again at their place; --explain lists each step's operator
events, --json adds "operator_events" and "expected_operator_events".

Examples:
  pearl replay bags/table4_clarification
  pearl replay bags/figure4_guidance --json
  pearl replay bags/table4_clarification --explain
"""
from __future__ import annotations

import argparse
import os

from pearl_pomdp.cli._progress import add_progress_arguments, show_progress

COMMAND = "replay"
HELP = "replay a bag's inputs through tracker + policy under sim time; compare with the recorded actions"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("bag", metavar="BAG", help="bag directory or .mcap file")
    parser.add_argument("--domain", help="domain file (default: the bag's custom_data pearl.domain)")
    parser.add_argument("--policy", help="planned policy directory (default: the bag's custom_data pearl.policy)")
    parser.add_argument("--domain-id", type=int, help="ROS domain of the replay (default: $ROS_DOMAIN_ID)")
    parser.add_argument("--step-timeout", type=float, default=10.0, metavar="S",
                        help="wall seconds to wait for the graph's reaction to one message (default 10)")
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    parser.add_argument("--explain", action="store_true",
                        help="per step: what closed it, the belief after, the EXECUTE trace with values; "
                             "the first divergence from the recording")
    add_progress_arguments(parser)


def run(args: argparse.Namespace) -> int:
    from pearl_pomdp.nodes.bag_replay import replay_bag
    from pearl_pomdp.cli import print_json

    domain_id = args.domain_id
    if domain_id is None and os.environ.get("ROS_DOMAIN_ID", "").isdigit():
        domain_id = int(os.environ["ROS_DOMAIN_ID"])
    result = replay_bag(args.bag, domain=args.domain, policy=args.policy, domain_id=domain_id,
                        step_timeout_s=args.step_timeout, progress=show_progress(args), explain=args.explain)
    if args.json:
        print_json(result.to_dict())
    else:
        print(f"bag:       {result.bag}")
        print(f"actions:   {' '.join(result.actions)}")
        print(f"expected:  {' '.join(result.expected_actions)}")
        status = "yes" if result.match else f"NO (first difference at action {result.first_mismatch})"
        print(f"match:     {status}")
        print(f"messages:  {result.messages} in {result.seconds:.3f} s ({result.messages_per_second:.0f} msg/s)")
        print(f"tracker:   step rules and places from {result.tracker_params_from}"
              + (" (the bag recorded none: the params file's)" if result.tracker_params_from == "defaults" else ""))
        if result.explanation is not None:
            print(format_explanation(result.explanation, result.divergence))
    return 0 if result.match else 1


def _trace_text(trace) -> str:
    parts = []
    for t in trace or []:
        value = t.get("value")
        text = f"{t.get('subtask')}→{t.get('choice')} ({'–' if value is None else f'{value:.2f}'}"
        if t.get("runner_up"):
            rival = t.get("runner_up_value")
            text += f"; next {t['runner_up']} {'–' if rival is None else f'{rival:.2f}'}"
        parts.append(text + ")")
    return "  ".join(parts)


def search_lines(search) -> list:
    """An online decision's search, for --explain: its size, the root's bounds, and the top of the
    tree (the best actions by lower bound with their observation branches)."""
    if not search:
        return []
    lines = [f"        search: {search.get('trials')} trials, {search.get('nodes')} nodes, root "
             f"[{search.get('lower', 0.0):.2f}, {search.get('upper', 0.0):.2f}] gap {search.get('gap', 0.0):.2f}, "
             f"{search.get('seconds', 0.0) * 1e3:.0f} ms, stopped by {search.get('stop')}"]
    for a in (search.get("top") or {}).get("actions", []):
        branches = ", ".join(f"o{c['observation']} {c['share']:.0%} [{c['lower']:.2f}, {c['upper']:.2f}]"
                             for c in a.get("children", []))
        lines.append(f"          {a['action']}: [{a['lower']:.2f}, {a['upper']:.2f}]  {branches}")
    return lines


def _operator_lines(step) -> list:
    """The operator's events at this step's belief (veto, waiting, yes/no, command, level), one line each."""
    return [f"        operator: {e['event']} {e['action']}" + (f" ({e['detail']})" if e.get("detail") else "")
            for e in step.get("operator") or []]


def format_explanation(steps, divergence) -> str:
    """The --explain text: one block per step, then the first divergence."""
    lines = ["", "why:"]
    for s in steps:
        d = s["decision"]
        if s["closed_by"] is None:
            lines.append(f"  [b0] → {d['action']}   {_trace_text(d['trace'])}")
            lines.extend(search_lines(d.get("search")))
            lines.extend(_operator_lines(s))
            continue
        c = s["closed_by"]
        heard = f"{c['input']} {c['text']!r} → {c['symbol']}"
        if c["input"] == "speech" and c["confidence"] < 1.0:
            heard += f" (confidence {c['confidence']:.2f})"
        if c["zero_likelihood"]:
            heard += " (zero likelihood: recovered)"
        belief = ", ".join(f"{f}={v} {p:.2f}" for f, (v, p) in s["belief"].items())
        lines.append(f"  [{s['step']:>3}] {s['time']:8.1f} s  after {s['action']}: {heard}")
        lines.append(f"        belief {belief}")
        lines.append(f"        → {d['action']}   {_trace_text(d['trace'])}")
        lines.extend(search_lines(d.get("search")))
        lines.extend(_operator_lines(s))
    if divergence:
        lines.append(f"first divergence at action {divergence['action_index']}: replayed {divergence['replayed']}, "
                     f"recorded {divergence['recorded']}")
        lines.append(f"  replayed trace: {_trace_text(divergence['replayed_trace'])}")
        recorded = divergence["recorded_trace"]
        lines.append(f"  recorded trace: {_trace_text(recorded) if recorded else '(the bag has no /pearl/decision)'}")
    return "\n".join(lines)
