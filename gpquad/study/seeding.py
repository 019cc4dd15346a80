"""Every seed of a study, derived from the config's master seed (one place).

- `target_seed`: one target of `gpquad run`: SeedSequence([seed, target_index]), so a
  target's result does not depend on which other targets are run.
- `run_seed`: run (target, k) of a sweep: SeedSequence(seed).spawn(7)[target_index]
  .spawn(k + 1)[k], so a run depends on neither the number of jobs nor the finishing order.
- `assembly_seed`: full model k of a sweep (bootstrap draw and input noise): child 6 of the
  root, spawn(k + 1)[k].
"""

from __future__ import annotations

import numpy as np

from gpquad.engine.variables import TARGET_NAMES, target_index

#: Index of the root seed's child that seeds full-model assembly (after the six targets).
ASSEMBLY_CHILD = len(TARGET_NAMES)


def target_seed(master_seed: int, target: str) -> np.random.SeedSequence:
    """Seed of one target's run: independent of which other targets are run."""
    return np.random.SeedSequence([int(master_seed), target_index(target)])


def run_seed(master_seed: int, target: str, repetition: int) -> np.random.SeedSequence:
    """Seed of sweep run (target, repetition), spawned from the master seed."""
    per_target = np.random.SeedSequence(int(master_seed)).spawn(len(TARGET_NAMES) + 1)
    return per_target[target_index(target)].spawn(repetition + 1)[repetition]


def assembly_seed(master_seed: int, index: int) -> np.random.SeedSequence:
    """Seed of full model `index` (bootstrap draw and input noise)."""
    child = np.random.SeedSequence(int(master_seed)).spawn(ASSEMBLY_CHILD + 1)[ASSEMBLY_CHILD]
    return child.spawn(index + 1)[index]
