"""The ROS 2 side: the lifecycle node, its parameters, persistence, and the DDS tools.

The only package that imports rclpy (lazily, in the modules that need it), so that the rest
of prsm_health runs without ROS.
"""
