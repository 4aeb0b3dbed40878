"""The ROS-free core: vehicle data, model, integrators, EKF, noise adaptation, identification."""
import os

from .compiled_cache import register

# The files holding the numba code compiled with cache=True and every core module that code
# reads (it freezes their constants and inlines their functions): numba's cache of each is
# keyed on all of them together (compiled_cache.py). test_ekf checks the list is complete.
COMPILED_SOURCES = ('errors.py', 'state.py', 'vehicle.py', 'monomials.py', 'current_terms.py',
                    'planar.py',
                    'model.py', 'ekf.py', 'timing.py', 'propagation.py')

register(os.path.dirname(os.path.abspath(__file__)), COMPILED_SOURCES)
