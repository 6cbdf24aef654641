"""Online planning: DESPOT over a generative model, with the project's offline bounds as heuristics.

Everything else in Pearl plans offline; this package plans at each step from the current belief
(docs/online.md). It is ROS-free.

* :mod:`~pearl_pomdp.online.generative` — the :class:`GenerativeModel` protocol
  (``step(states, action, uniforms) -> (next_states, observations, rewards)``, vectorised over
  particles and deterministic given the uniforms, DESPOT's "deterministic simulative model"),
  :class:`ExplicitModel` (the adapter for a :class:`~pearl_pomdp.model.pomdp.Pomdp`'s arrays)
  and the bounds the search starts from.
* :mod:`~pearl_pomdp.online.despot` — the anytime DESPOT search (Ye, Somani, Hsu & Lee, JAIR 2017)
  under a deterministic trial budget (a wall-clock cap only as a guard).
* :mod:`~pearl_pomdp.online.beliefs` — root beliefs that cannot starve: the exact belief of an
  explicit model, RockSample's exact factored belief, a particle filter with reinvigoration.
* :mod:`~pearl_pomdp.online.rocksample` — RockSample (Smith & Simmons 2004) as a generative model.
* :mod:`~pearl_pomdp.online.decider` — :class:`OnlineDecider`, the search as a
  :class:`~pearl_pomdp.interfaces.Decider`.
"""
