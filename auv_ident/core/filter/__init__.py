"""The augmented-state EKF: compiled step algebra (ekf), the filter object (augmented), its
use over a stream of samples (stream), covariance propagation and the time base (timing)."""
