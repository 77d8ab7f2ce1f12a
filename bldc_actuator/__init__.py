"""bldc_actuator: a virtual BLDC/PMSM actuator (q-axis model) and a diagnosis tool.

The physics (``frames``, ``params``, ``effects``, ``model``) imports without ROS; ``node`` needs rclpy.
"""

__version__ = "0.1.0"
