"""Identification methods over recorded runs and their statistics: the filter-error batch
pass and refinement, the noise model, the choice of coefficients, uncertainty and diagnosis,
and the comparison methods (UKF, output error, equation error, thrust fit)."""
