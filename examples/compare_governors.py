"""The picture of docs/governors.md, "Three governors on one engine": the bundled scenes engine_direct (Porter),
engine_hartnell and engine_pi run through the same load steps (6 -> 8 N m at 2 s, full load rejection at 9 s); their
cycle-mean speeds and throttles against time.
Run: `python examples/compare_governors.py docs/images/governors_compared.png`.
"""

import sys

import matplotlib.pyplot as plt
import numpy as np

from mech_regulator.analysis import cycle_mean_speed
from mech_regulator.model import build_model
from mech_regulator.scene import load_scene
from mech_regulator.solvers import simulate

SCENES = {"engine_direct": "Porter, direct", "engine_hartnell": "Hartnell, direct", "engine_pi": "electronic PI"}


def main(path: str) -> None:
    """Simulate the three scenes and write the picture to path."""
    figure, (speed, throttle) = plt.subplots(2, 1, figsize=(11, 7), sharex=True, constrained_layout=True)
    for name, label in SCENES.items():
        model = build_model(load_scene(name))
        trajectory = simulate(model)
        times = np.linspace(0.0, model.scene.scenario.duration, 4001)
        (line,) = speed.plot(times, cycle_mean_speed(model, trajectory, times), lw=1.2, label=label)
        columns = model.columns(times, trajectory(times))
        throttle.plot(times, columns["throttle"], lw=0.5, color=line.get_color(), alpha=0.8, label=label)
    for event in (2.0, 9.0):
        for axis in (speed, throttle):
            axis.axvline(event, color="0.6", lw=0.6, ls=":")
    speed.set(
        ylabel="cycle-mean crank speed [rad/s]",
        title="load 6 -> 8 N m at 2 s, thrown off at 9 s: the Porter and Hartnell sensors leave a static "
        "error, the PI none",
    )
    throttle.set(xlabel="t [s]", ylabel="throttle [-] (within the cycle)", ylim=(-0.05, 1.05))
    speed.legend(loc="upper left")
    throttle.legend(loc="lower left")
    figure.savefig(path, dpi=100)


if __name__ == "__main__":
    main(sys.argv[1])
