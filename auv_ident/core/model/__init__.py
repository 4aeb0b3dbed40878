"""The vehicle and its equations: state layout, vehicle files, the 6-DOF hydrodynamic model
(compiled term tables), the water current, integrators, trim and the sensor defaults."""
