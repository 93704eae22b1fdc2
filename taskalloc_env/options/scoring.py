"""Scoring (thesis §3.2.2, (3.8)–(3.11); §5.3.1): the named options of ``scoring.ScoringModel``."""

from __future__ import annotations

from taskalloc_env.fields import Field, group

SCORING_GROUP = group("scoring", (
    Field('distance_cost', 'choice', choices=('from_start', 'leg'), default='leg',
          meaning=('`leg` (γ × the distance flown into the task; a path costs γ × its length) \\| `from_start` (γ × '
                   "the straight distance from the agent's start, the same on every path) — see "
                   '[decisions](decisions.md)'),
          source='thesis (3.9); `from_start`: the public MIT CBBA code'),
    Field('marginal_gain', 'choice', choices=('rescore', 'frozen'), default='rescore',
          meaning=('`rescore` ((3.11): later tasks re-timed) \\| `frozen` (existing start times may not move)'),
          source='thesis (3.11); Johnson §3.3.1 (3.2), §3.4.1 (3.6)'),
    Field('reward_time', 'choice', choices=('arrival', 'start'), default='arrival',
          meaning=('(3.8) discounts from the arrival τ, no earlier than the window start: c̄ e^{−λ max(0, τ − '
                   'start_j)} \\| `start` (from the start of service, which prerequisites can hold back)'),
          source='thesis (3.8) and its text'),
    Field('prereq_timing', 'choice', choices=('conservative', 'earliest', 'none'), default='conservative',
          meaning='follow-up starts ≥ end_m + dur_m \\| `earliest` (≥ start_m + dur_m) \\| `none`',
          source='choice (thesis §3.1.3 gives no timing rule)'),
    Field('reward_split', 'choice', choices=('per_agent', 'total'), default='per_agent',
          meaning='every member earns c̄_j \\| `total` (c̄_j / L_j each, E3.7)',
          source='thesis §3.2.2; §3.3.3 (E3.7: 150 per task in total)'),
    Field('travel_metric', 'choice', choices=('euclidean', 'manhattan'), default='euclidean',
          meaning=('the distance agents fly, for travel times, costs and `max_travel`: `euclidean` (‖·‖, straight '
                   'flight) \\| `manhattan` (Σ \\|Δ\\| over the axes: moves along a grid, one unit per cell)'),
          source='thesis (3.8)–(3.9) (‖·‖); `manhattan`: ours, for the DCTA benchmark\'s grid moves'),
    Field('conflict_policy', 'choice', choices=('first_L_paid', 'none_paid'), default='first_L_paid',
          meaning='more than L_j members: the first L_j starters are paid \\| `none_paid`',
          source='choice (conflicts: thesis §4.3)'),
))
