"""The network (``network.Network``, ``network.CommGraph``): the communication graph (thesis §4.3) and the faults,
which are ours (the sources assume every message arrives)."""

from __future__ import annotations

from taskalloc_env.faults import LOSS_MODELS
from taskalloc_env.fields import MAX_COUNT, Field, group

NETWORK_GROUP = group("network", (
    Field('comm_range', 'number', low=0, optional=True, default=None,
          meaning=('communication range r (km); agents link by their start positions and bids travel multi-hop '
                   '(messages are forwarded whole); null = every agent hears every other'),
          source='thesis §4.3 (Figs 4.2–4.7)'),
    Field('edge_rule', 'choice', choices=('dist', 'circles_overlap'), default='dist',
          meaning=('`dist` (link when distance ≤ r: circles of radius r/2 overlap) \\| `circles_overlap` (≤ 2r: '
                   'circles of radius r overlap)'),
          source=('thesis §4.3: "any overlapping circles show the available communication channels"; the radius is '
                  'not stated, so which circles is a choice')),
    Field('message_loss', 'probability', default=0.0,
          meaning=('p in [0, 1]: each message (one sender → one receiver) is lost independently with probability p; '
                   'with `gilbert_elliott`, the loss in the good state; with `gilbert_elliott_rho`, the stationary '
                   'loss rate ℓ = 1 − q (q the stationary delivery rate)'),
          source=('beyond the sources (Johnson §2.2 "Communication Environment" and §3.5.1 name unreliable links as '
                  'the reason for ACBBA but model none)')),
    Field('loss_model', 'choice', choices=tuple(LOSS_MODELS), default='independent',
          meaning=('`independent` (Bernoulli) \\| `gilbert_elliott`: each link is a two-state channel, so losses '
                   'come in bursts (Gilbert 1960, Elliott 1963), set by its transition probabilities `burst_*` \\| '
                   '`gilbert_elliott_rho`: the same channel set by its stationary loss `message_loss` and lag-1 '
                   'correlation `burst_correlation`, a loss-free good and an all-losing bad state \\| `rayleigh`: a '
                   'message over distance d arrives with probability exp(−(d / `fading_distance`)^`fading_exponent`)'),
          source=('beyond the sources; `gilbert_elliott_rho` and `rayleigh` follow the channel models of Nayak et al., '
                  'IEEE RA-L 2020 and its 2026 successor, the DCTA benchmark (derivations: `faults.py`)')),
    Field('burst_enter', 'probability', default=0.05,
          meaning='per round, probability a link in the good state turns bad (`gilbert_elliott` only)',
          source='beyond the sources'),
    Field('burst_leave', 'probability', default=0.5,
          meaning='per round, probability a bad link recovers (mean burst 1 / 0.5 = 2 rounds)',
          source='beyond the sources'),
    Field('burst_loss', 'probability', default=1.0,
          meaning='loss probability in the bad state',
          source='beyond the sources'),
    Field('burst_correlation', 'number', low=0, high=1, strict_high=True, default=0.8,
          meaning=('ρ in [0, 1): lag-1 correlation of a link\'s state under `gilbert_elliott_rho`, so '
                   'P(good → bad) = ℓ (1 − ρ), P(bad → good) = (1 − ℓ)(1 − ρ); ρ = 0 is `independent`'),
          source=('the DCTA benchmark\'s Gilbert–Elliott process (p_GG = q + ρ(1 − q), p_BB = (1 − q) + ρq, '
                  'fixed ρ = 0.8)')),
    Field('fading_distance', 'number', low=0, strict=True, default=5.0,
          meaning=('d0 > 0 (km) under `rayleigh`: the distance at which a message arrives with probability '
                   'e^−1 ≈ 0.37 (the mean received power equals the reception threshold)'),
          source=('Rayleigh outage probability (Goldsmith 2005, ch. 3); the value is ours (the default arena\'s '
                  'side)')),
    Field('fading_exponent', 'number', low=0, strict=True, high=10, default=2.0,
          meaning='path-loss exponent α in (0, 10] under `rayleigh` (2: free space)',
          source=('Rayleigh outage probability; the DCTA benchmark tuned α = 3 (from 2.5) for its grid; 2 is '
                  'free-space propagation')),
    Field('max_delay', 'int', low=0, time_like=True, default=0,
          meaning=('integer d ≥ 0: each message arrives after a uniform 0..d extra rounds (ticks), so rounds overlap'
                   ' and old messages can arrive after newer ones; the timestamps of thesis (2.4) order them'),
          source='beyond the sources (Johnson §2.2: "no guarantees … what the message latencies will be")'),
    Field('dropouts', 'int', low=0, high=MAX_COUNT, default=0,
          meaning=('number of agents (0..N − 1) that fail at random: they stop sending and receiving, fly nothing '
                   'and leave `env.agents` (terminated)'),
          source=('Johnson §2.2 ("agents may enter and leave the network … comm drop out"), "Tasking Environment" '
                  '("teammate agents coming off-line and on-line mid-convergence"); the failure model is ours')),
    Field('dropout_rounds', 'ints', shape='two rounds [earliest, latest]', low=1, length=2, time_like=True,
          default=(1, 10),
          meaning='[earliest, latest] round of a random failure, drawn uniformly per failing agent',
          source='choice'),
    Field('dropout_schedule', 'record', optional=True, default=None,
          meaning=('explicit `[[agent, round], …]` failures (instead of `dropouts`; each agent at most once; a round'
                   ' past the round bound is an error)'),
          source='choice'),
    Field('join_at', 'record', optional=True, default=None,
          meaning=('late joiners `{agent: round, …}` (or `[[agent, round], …]`): each listed agent is absent from '
                   '`env.agents` and neither sends nor receives until that round (tick under `acbba`), then enters '
                   'knowing nothing but what it hears; rounds 1 … the round bound, at least one agent present from '
                   'the start'),
          source=('Johnson §2.2 ("agents may enter and leave the network"), ch. 4 goal 4 ("Allow agents to enter '
                  'and leave the network"); the joining model is ours')),
    Field('silence_timeout', 'int', low=1, optional=True, time_like=True, default=None,
          meaning=('rounds without hearing from or about an agent (its timestamp s_i[k], relayed stamps included) '
                   "after which an agent clears that agent's bids from its table, so its tasks can be re-assigned; "
                   'null = 2 · (D + 1) (under `acbba`: × the tick factor of the round bound, see below)'),
          source=('beyond the sources: Johnson §3.5.1 notes that a synchronous scheme waiting for a message "that '
                  'was not going to arrive" deadlocks; the timeout and its value are ours')),
))
