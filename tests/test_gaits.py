"""experiments/gaits.py: a halfcheetah's torso is on its back where its pitch is past 90
degrees either way, whatever the angle's winding."""

import numpy as np

from experiments.gaits import flipped


def test_a_pitch_past_ninety_degrees_either_way_is_on_its_back_at_any_winding():
    upright = np.array([0.0, 0.3, -1.5, 2 * np.pi + 0.2, -2 * np.pi - 1.0])
    back = np.array([np.pi, -np.pi, 1.7, -1.7, 3 * np.pi - 0.5, -4 * np.pi + 2.0])
    assert not flipped(upright).any()
    assert flipped(back).all()
