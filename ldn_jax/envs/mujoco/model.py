"""gymnasium's v5 MuJoCo models, compiled once per process and without compiler warnings.

Both engines step the very model files gymnasium's v5 envs load (from the installed
gymnasium's `envs/mujoco/assets`), so a policy trained here is evaluated on the task it learned.
"""

from __future__ import annotations

import contextlib
import functools
import os
import re
import sys

import mujoco
import numpy as np

TOTAL_MASS = re.compile(r'\s*settotalmass="([^"]*)"')


class ModelError(ValueError):
    """The mujoco library cannot load or compile a task's model."""


def asset_path(asset: str) -> str:
    import gymnasium  # its assets only; importing gymnasium's mujoco envs is not needed

    return os.path.join(os.path.dirname(gymnasium.__file__), "envs", "mujoco", "assets", asset)


@functools.cache
def load(asset: str) -> mujoco.MjModel:
    """Compile `asset` as gymnasium does.

    half_cheetah.xml sets `settotalmass`, which MuJoCo now warns about on every compile; the
    attribute is removed and its effect applied with `mj_setTotalmass` + `mj_setConst`, which
    gives the same compiled model to the bit (every float array compared).
    Raises `ModelError` with one line when the library cannot load the file.
    """
    path = asset_path(asset)
    try:
        with open(path) as f:
            xml = f.read()
        total_mass = TOTAL_MASS.search(xml)
        spec = mujoco.MjSpec.from_string(TOTAL_MASS.sub("", xml))
        spec.meshdir = spec.texturedir = os.path.dirname(path)
        model = spec.compile()
    except (OSError, ValueError, mujoco.FatalError) as error:
        message = str(error).strip().splitlines()[0] if str(error).strip() else type(error)
        raise ModelError(f"mujoco {mujoco.__version__} cannot load {path}: {message}") from None
    if total_mass is not None:
        mujoco.mj_setTotalmass(model, float(total_mass.group(1)))
        mujoco.mj_setConst(model, mujoco.MjData(model))
    return model


def state_size(model: mujoco.MjModel) -> int:
    """Length of MuJoCo's full physics state (time, qpos, qvel, act, ...)."""
    return mujoco.mj_stateSize(model, mujoco.mjtState.mjSTATE_FULLPHYSICS)


def body_ids(model: mujoco.MjModel, names: tuple[str, ...]) -> np.ndarray:
    """Body indices of `names` in `model` (int32 `[len(names)]`)."""
    ids = [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, name) for name in names]
    return np.asarray(ids, np.int32)


@contextlib.contextmanager
def settotalmass_ignored():
    """While open, MuJoCo's warning about half_cheetah.xml's deprecated `settotalmass` is
    dropped; every other warning still goes to stderr. For code that compiles gymnasium's
    model itself (gymnasium's HalfCheetah-v5); `load` avoids the warning instead."""
    previous = mujoco.get_mju_user_warning()

    def handler(message: str) -> None:
        if "settotalmass" not in message:
            print(f"WARNING: {message}", file=sys.stderr)

    mujoco.set_mju_user_warning(handler)
    try:
        yield
    finally:
        mujoco.set_mju_user_warning(previous)
