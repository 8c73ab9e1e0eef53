"""mech_regulator: real motion of machines and the regulation of their speed (theory of machines).

The physics core (scene, model, mechanisms, effects, solvers, analysis) imports neither rclpy nor
rerun; the command line and, later, the ROS nodes and viewers are thin layers over it.
"""

__version__ = "0.1.0"
