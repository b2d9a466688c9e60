"""The model's kernels give the same bits compiled in the running process as loaded from
numba's cache (docs/scale.md "Issue 26, session 38"): before, the consistent model's poses moved
by up to 7e-16 rad between the two (numba linked ``_equilibrium`` and the parallel loop's body
into ``solve`` as copies it optimised again, whose fused multiply-adds rounded otherwise), so the
first run after its kernel was compiled gave another noise-free estimate than every run after
it. Needs the test process's kernels loaded from the cache (``setup.sh`` compiles them)."""

import os
import subprocess
import sys

import numpy as np
import pytest


def model_poses(out: str) -> None:
    """The consistent and second-order models' poses (table1's true values and 5 random
    candidates, the standard trajectory, on 1 and 2 threads) saved to ``out`` (.npz)."""
    from flexcal.model.forward import forward
    from flexcal.model.trajectory import standard_trajectory
    from flexcal.validation.prototype.scenario import load_scenario
    from flexcal.validation.runs.model_correction import model_space

    poses = {}
    for model in ("consistent", "second-order"):
        space = model_space("closed-form", model=model)
        rng = np.random.default_rng(0)
        values = np.concatenate([load_scenario("table1").values[None], space.from_unit(rng.random((5, 45)))])
        for threads in (1, 2):
            result = forward(values, standard_trajectory(space.mechanism).inputs, space=space, engine="numba",
                             n_threads=threads)
            poses[f"{model} {threads}"] = result.pose
    np.savez(out, **poses)


@pytest.mark.slow
def test_a_kernel_compiled_in_the_process_gives_the_bits_of_the_cached_one(tmp_path):
    # a child with an empty numba cache compiles every kernel in its own process (~2-6 min)
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "numba"))
    subprocess.run([sys.executable, __file__, str(tmp_path / "compiled.npz")], env=env, cwd=tmp_path, check=True,
                   timeout=1800)
    model_poses(str(tmp_path / "cached.npz"))  # this process: the kernels as the test run has them
    compiled, cached = np.load(tmp_path / "compiled.npz"), np.load(tmp_path / "cached.npz")
    assert sorted(compiled.files) == sorted(cached.files)
    for key in cached.files:
        assert np.array_equal(compiled[key], cached[key]), key  # the same bits, not merely close
    assert np.array_equal(cached["consistent 1"], cached["consistent 2"])


if __name__ == "__main__":
    model_poses(sys.argv[1])
