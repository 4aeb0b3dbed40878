"""ament_python package auv_ident (colcon build / ros2 run, or pip install -e . in a venv)."""
from glob import glob
import os

from setuptools import find_packages, setup

package_name = 'auv_ident'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test', 'test.*']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        (os.path.join('share', package_name, 'config'), glob('config/*.yaml')),
        (os.path.join('share', package_name, 'config', 'inputs'), glob('config/inputs/*.yaml')),
        (os.path.join('share', package_name, 'bags', 'nps_auv2_ident'),
         glob('bags/nps_auv2_ident/*')),
    ],
    install_requires=['setuptools'],
    zip_safe=False,  # numba compiles from the source files (core/compiled_cache.py)
    maintainer='auv_ident developers',
    maintainer_email='auv_ident@example.com',
    description='Identification of AUV hydrodynamic coefficients with an augmented-state EKF '
                'and ARMA/innovation-based noise adaptation (Zare Ernani et al. 2015).',
    license='MIT',
    tests_require=['pytest'],
    entry_points={
        'console_scripts': [
            'auv_ident = auv_ident.cli:main',
            'simulator = auv_ident.ros.simulator_node:main',
            'identifier = auv_ident.ros.identifier_node:main',
            'record = auv_ident.ros.record_node:main',
            'play = auv_ident.ros.play_node:main',
        ],
    },
)
