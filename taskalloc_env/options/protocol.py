"""The consensus protocol (thesis §3.2, §4.2, §5.2; Johnson §3.4.1): read by ``protocol``, ``bidding``, ``groups``
and ``cbba_table``."""

from __future__ import annotations

from taskalloc_env.fields import MAX_COUNT, Field, group

PROTOCOL_GROUP = group("protocol", (
    Field('cbba_table', 'choice', choices=('canonical', 'thesis'), default='canonical',
          meaning="Choi 2009's table \\| `thesis` (the thesis's transcription, two cells differ)",
          source='Johnson §3.4.1, Table 3.1; thesis Table 2.1'),
    Field('prereq_mode', 'choice', choices=('all_have_bid', 'all_complete', 'any_has_bid'), default='all_have_bid',
          meaning='every prerequisite has a bid \\| `all_complete` \\| `any_has_bid`',
          source='thesis (3.6); article eq. (5)'),
    Field('release_order', 'choice', choices=('bundle', 'path'), default='bundle',
          meaning='release what was added after the lost task \\| `path` (what is scheduled after it)',
          source='Johnson (3.11)–(3.12); thesis §2.2.4'),
    Field('require_known_capacity', 'bool', default=False,
          meaning=('bid on L_j > 1 only when L_j capable agents are known; agents then start knowing only themselves'),
          source='choice, after thesis §4.2.2, §4.3'),
    Field('task_quitting', 'bool', default=False,
          meaning='quit actions allowed (Alg 9)',
          source='thesis §5.2.2'),
    Field('release_actions', 'bool', default=False,
          meaning=('release actions allowed: an agent may drop a task of its own bundle and every task after it, as '
                   'an outbid release does (the action space grows to 1 + 3M)'),
          source='ours (the release rule: thesis §2.2.4; Johnson (3.11)–(3.12)); PI needs it (Zhao et al. 2016)'),
    Field('release_guard', 'choice', choices=('none', 'exchange', 'once'), default='none',
          meaning=('with `release_actions`, a task can be released at any step \\| `exchange`: only in a later round '
                   '(tick) than the agent\'s bid on it, once an exchange has brought the others\' bids, so no '
                   'bid–release cycle can hold a round open \\| `once`: as `exchange`, and each agent releases each '
                   'task at most once, so the releases of an episode are finite'),
          source=('ours; `exchange` after Johnson §4.2 (a replan follows new situational awareness), `once` after '
                  'the once-per-task quit (thesis §5.2.2, Alg 9)')),
    Field('delta', 'int', low=0, time_like=True, default=1,
          meaning=('δ: rounds an incomplete group is held before a quit is allowed; the scripted CBGA+TQ and CBGABI '
                   'quit with this δ'),
          source='thesis Alg 9 l. 6; δ = 1 in Fig 5.9'),
    Field('reset_on', 'choice', choices=('additions', 'any_change'), default='additions',
          meaning='the group timer restarts when a member joins \\| `any_change`',
          source='thesis §5.2.2, Alg 9 l. 4–5'),
    Field('quit_block', 'choice', choices=('until_joined', 'none'), default='until_joined',
          meaning=('after quitting, no re-bid on the task until another agent joins it (a member leaving does not '
                   'lift it) \\| `none` (re-bid at once)'),
          source='article, after eq. (10); `none`: thesis §5.2.2, §5.3.2'),
    Field('outbid_ties', 'choice', choices=('strict', 'higher_id'), default='strict',
          meaning=('in the bundle phase an equal bid never outbids \\| `higher_id` (an equal bid from a higher id '
                   'does); the consensus always orders equal bids by the higher id'),
          source='thesis Alg 5 l. 12, 18; §3.2.2–3.2.3'),
    Field('bid_warping', 'bool', default=True,
          meaning=("the shared bid is min(c_ij, the agent's earlier bundle bids), so shared bids never rise along a "
                   'bundle \\| false (share c_ij)'),
          source='ours; Johnson §4.3 only alludes to unpublished work ("as long as external bids follow DMG")'),
    Field('consensus', 'choice', choices=('sync', 'every_step', 'acbba'), default='sync',
          meaning=('exchange when every agent has passed \\| `every_step` \\| `acbba` (asynchronous: one step is one '
                   'tick, see below)'),
          source='thesis §3.2.3 (`sync`); `every_step`: ours; Johnson §4.1 (`acbba`)'),
    Field('max_bundle', 'int', low=1, high=MAX_COUNT, optional=True, default=None,
          meaning='M_m, the bundle cap (null = N_m, no cap)',
          source='thesis §3.1.1–3.1.2'),
    Field('max_rounds', 'int', low=1, optional=True, time_like=True, default=None,
          meaning='T_max (null = 10 · max(N_m, N_n · max L_j) · D)',
          source='choice'),
))
