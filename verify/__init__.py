"""Headless MuJoCo verification of an exported mechanism, and its playback (meshcat, matplotlib).

from linkd.verify import verify_output
report = verify_output("out")  # checks out/mechanism.xml against out/mechanism.json
"""

from .animation import write_animation
from .plot import write_curve_plot
from .pose import solve_pose, solve_sweep
from .report import Report
from .runner import verify_output

__all__ = ["Report", "solve_pose", "solve_sweep", "verify_output", "write_animation",
           "write_curve_plot"]  # fmt: skip
