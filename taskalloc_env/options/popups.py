"""Pop-up tasks (Johnson §4.1.3, Figs 4-3/4-4), read by ``releases``: the last ``popup_tasks`` task ids appear
during the episode."""

from __future__ import annotations

from taskalloc_env.fields import MAX_COUNT, Field, group

POPUP_GROUP = group("popups", (
    Field('popup_tasks', 'int', low=0, high=MAX_COUNT, default=0,
          meaning='tasks released during the episode (0..N_m)',
          source='Johnson §4.1.3 (Figs 4-3, 4-4: 10 tasks seed the run, then pop-ups)'),
    Field('popup_period', 'int', low=1, time_like=True, default=200,
          meaning='ticks between releases (the mean for `poisson`)',
          source='Johnson §4.1.3: every 0.2 s (200 ticks at 1 ms) or 0.05 s'),
    Field('popup_arrivals', 'choice', choices=('periodic', 'poisson'), default='periodic',
          meaning=('`periodic`: one every period, the first at one period \\| `poisson`: the releases are '
                   '`popup_tasks` uniform draws over (0, count × period], a Poisson process conditioned on its count'),
          source='Johnson (periodic); choice (`poisson`)'),
    Field('popup_times', 'ints', low=0, optional=True, time_like=True, default=None,
          meaning='explicit release ticks, one per pop-up (overrides period and arrivals)',
          source='choice'),
    Field('mission_time_per_tick', 'number', low=0, default=0.0,
          meaning=('mission time (minutes under `km_min`) per tick: a task released at tick r cannot start before r '
                   "× this. 0: planning is instantaneous next to the mission (Johnson's consensus runs in ms, the "
                   'missions in minutes)'),
          source='choice (Johnson gives no mission clock)'),
))
