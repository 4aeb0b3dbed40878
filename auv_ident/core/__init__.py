"""The ROS-free core, in five parts that import one way:

    model  <-  filter  <-  identification  <-  glider
    model  <-  simulation  <-  glider

model/ (state layout, vehicle files, the hydrodynamic model, the current), filter/ (the
augmented EKF), identification/ (batch methods, noise model, choice of coefficients,
uncertainty, diagnosis), simulation/ (manoeuvres, simulator, prediction, zig-zags), glider/
(a buoyancy-driven glider's flight model and its calibration); errors.py, angles.py and
compiled_cache.py serve them all."""
import os

from auv_ident.core.compiled_cache import register

# The files holding the numba code compiled with a cache (compiled_cache.cached_njit) and every
# core module that code reads (it freezes their constants and inlines their functions): numba's
# cache of each is keyed on all of them together (compiled_cache.py). test_ekf checks the list
# is complete.
COMPILED_SOURCES = ('errors.py', 'model/state.py', 'model/vehicle.py', 'model/monomials.py',
                    'model/current_terms.py', 'model/planar.py', 'model/hydrodynamics.py',
                    'model/raw_sensors.py', 'model/thrusters.py', 'model/thruster_lag.py',
                    'vehicle_files.py',
                    'filter/ekf.py', 'filter/timing.py', 'filter/propagation.py',
                    'filter/raw_update.py', 'glider/flight.py', 'glider/record.py')

register(os.path.dirname(os.path.abspath(__file__)), COMPILED_SOURCES)
