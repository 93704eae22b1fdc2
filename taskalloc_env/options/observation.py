"""The observations (the learning interface, not in the sources), read by ``observation``."""

from __future__ import annotations

from taskalloc_env.fields import Field, group

OBSERVATION_GROUP = group("observation", (
    Field('team_features', 'bool', default=False,
          meaning=('true: every task block of the observation also holds `sooner_agents` (the other agents whose '
                   "straight flight from their start reaches the task sooner than this agent's, ÷ N) and "
                   '`nearest_other` (the shortest start distance of another agent to the task, ÷ the arena diagonal;'
                   ' 2 when alone) \\| false: the agent sees its own state, the tasks and its own tables only'),
          source=('choice (not in the sources, whose agents know the team only through its messages): it assumes '
                  "every agent knows every agent's start and speed at launch, as static common knowledge; the "
                  'protocol, the masks and every scripted policy are unchanged (they read columns by name). '
                  'docs/learning.md measures what it gives a learned bidder')),
))
