"""The asynchronous consensus, ``consensus = "acbba"`` (Johnson §4.1; times in ticks), read by ``async_protocol``
and ``async_consensus``."""

from __future__ import annotations

from taskalloc_env.fields import MAX_HORIZON, Field, group

ASYNC_GROUP = group("asynchronous", (
    Field('message_ticks', 'numbers', shape='two tick counts [fewest, most]', low=0, length=2, high=MAX_HORIZON,
          time_like=True,
          default=(0.0, 0.2),
          meaning=('[fewest, most] ticks the listener takes per message; each agent draws its own, uniformly, per '
                   'episode (fractions allowed; 0: every message the tick it arrives)'),
          source='Johnson §4.1.1 (the listener "run continuously"); values choice'),
    Field('build_ticks', 'ints', shape='two tick counts [fewest, most]', low=0, length=2, time_like=True,
          default=(1, 3),
          meaning=("[fewest, most] ticks from the builder's trigger to the agent being ready to decide; a per-agent "
                   'uniform integer draw'),
          source='Johnson §4.1.1 (throttled builder); values choice'),
    Field('separation_time', 'int', low=1, time_like=True, default=25,
          meaning=('ticks of its separation clock (`local_convergence`) after which an agent counts as locally '
                   'converged'),
          source='Johnson §4.1.3 (separation time); value measured ([decisions](decisions.md))'),
    Field('local_convergence', 'choice', choices=('bundle', 'table'), default='bundle',
          meaning=("what an agent's local-convergence declaration waits on: its bundle and the records of the tasks "
                   'it holds unchanged for more than `separation_time` ticks, its builder idle \\| `table`: no '
                   'relevant information at all (any table change, a release, a failure notice) for that long'),
          source=('Johnson §4.1.3 l. 939 (agents that keep their bundles converge while others negotiate); `table`: '
                  'l. 941 read literally ([decisions](decisions.md))')),
    Field('termination', 'choice', choices=('auto', 'global', 'local'), default='auto',
          meaning=('`global`: the episode ends when the network is quiet \\| `local`: when every live agent is '
                   'locally converged \\| `auto`: local with pop-up tasks, global otherwise'),
          source='Johnson §4.1.3'),
    Field('confirmations', 'int', low=0, optional=True, time_like=True, default=None,
          meaning=('full-state announcements an agent makes, after `separation_time` quiet ticks, before it counts '
                   'as converged; null: 2 when messages can be lost, else 0'),
          source='choice (not in Johnson)'),
    Field('acbba_row11', 'choice', choices=('update', 'trust_later'), default='update',
          meaning=('row 11 (sender k, receiver m, y_k > y_i, t_k < t_i): the cell \\| `trust_later` (the remark)'),
          source='Johnson Table 4.1 row 11; remark l. 879'),
    Field('acbba_row15', 'choice', choices=('leave_bump', 'leave', 'empty'), default='leave_bump',
          meaning='row 15: the cell (leave‡ & rebroadcast) \\| `leave` \\| `empty` (not in the thesis)',
          source='Johnson Table 4.1 row 15; design note §8.22'),
    Field('acbba_row20_guard', 'bool', default=True,
          meaning='row 20 updates only if t_k ≥ t_i (the remark); false: the unconditional cell',
          source='Johnson remark l. 893; design note §2.5'),
    Field('acbba_row28_guard', 'bool', default=True,
          meaning='row 28 likewise',
          source='Johnson remark l. 899–901'),
    Field('acbba_equal_bids', 'choice', choices=('trust_later', 'leave'), default='trust_later',
          meaning=('an equal bid of another agent (row 9, and m \\| n with equal bids): adopt it if its time is later'
                   ' \\| `leave` (the cell and the default)'),
          source='choice, after Johnson\'s "trust the later timestamp" (l. 879, 897)'),
    Field('acbba_outbid_time', 'choice', choices=('bump', 'sender'), default='sender',
          meaning=("the time an outbid receiver gives the winner's record: the sender's \\| `bump` (the † reading: "
                   "later than the receiver's losing time, l. 875)"),
          source='choice by measurement ([decisions](decisions.md))'),
    Field('acbba_time_refresh', 'choice', choices=('epsilon', 'now'), default='epsilon',
          meaning=("a winner confirming its bid moves its time ε past the sender's \\| `now` (to the current tick)"),
          source='Johnson l. 875 (ε) and l. 871 (current time)'),
    Field('acbba_ties', 'choice', choices=('lowest_id', 'higher_id'), default='lowest_id',
          meaning=("equal bids in rows 2 and 18: the lower id wins (Johnson) \\| `higher_id` (the repository's CBBA)"),
          source='Johnson l. 875, 891'),
))
