"""PettingZoo's own test utilities on the default scenario, with default arguments (no special-casing)."""

import types
import warnings

from pettingzoo.test import (
    api_test,
    max_cycles_test,
    parallel_api_test,
    parallel_seed_test,
    render_test,
    seed_test,
    state_test,
)

from taskalloc_env import taskalloc_v0


def main() -> list[str]:
    warnings.simplefilter("ignore", UserWarning)    # api_test warns that a Dict observation is not a Box
    parallel_api_test(taskalloc_v0.parallel_env(), num_cycles=300)
    parallel_seed_test(taskalloc_v0.parallel_env)
    api_test(taskalloc_v0.env(), num_cycles=300)
    seed_test(taskalloc_v0.env)
    max_cycles_test(types.SimpleNamespace(parallel_env=taskalloc_v0.parallel_env, env=taskalloc_v0.env))
    render_test(lambda render_mode: taskalloc_v0.env(render_mode=render_mode))
    state_test(taskalloc_v0.env(), taskalloc_v0.parallel_env())
    return ["parallel_api_test", "parallel_seed_test", "api_test", "seed_test", "max_cycles_test", "render_test",
            "state_test"]


if __name__ == "__main__":
    print("passed:", ", ".join(main()))
