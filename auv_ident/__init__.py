"""auv_ident: identify AUV hydrodynamic coefficients with an augmented-state EKF (ROS 2 Jazzy)."""

__version__ = '0.1.0'
