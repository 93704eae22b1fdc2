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
                   'with `gilbert_elliott`, the loss in the good state'),
          source=('beyond the sources (Johnson §2.2 "Communication Environment" and §3.5.1 name unreliable links as '
                  'the reason for ACBBA but model none)')),
    Field('loss_model', 'choice', choices=tuple(LOSS_MODELS), default='independent',
          meaning=('`independent` \\| `gilbert_elliott`: each link is a two-state channel, so losses come in bursts '
                   '(Gilbert 1960, Elliott 1963)'),
          source='beyond the sources'),
    Field('burst_enter', 'probability', default=0.05,
          meaning='per round, probability a link in the good state turns bad (`gilbert_elliott` only)',
          source='beyond the sources'),
    Field('burst_leave', 'probability', default=0.5,
          meaning='per round, probability a bad link recovers (mean burst 1 / 0.5 = 2 rounds)',
          source='beyond the sources'),
    Field('burst_loss', 'probability', default=1.0,
          meaning='loss probability in the bad state',
          source='beyond the sources'),
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
    Field('silence_timeout', 'int', low=1, optional=True, time_like=True, default=None,
          meaning=('rounds without hearing from or about an agent (its timestamp s_i[k], relayed stamps included) '
                   "after which an agent clears that agent's bids from its table, so its tasks can be re-assigned; "
                   'null = 2 · (D + 1) (under `acbba`: × the tick factor of the round bound, see below)'),
          source=('beyond the sources: Johnson §3.5.1 notes that a synchronous scheme waiting for a message "that '
                  'was not going to arrive" deadlocks; the timeout and its value are ours')),
))
