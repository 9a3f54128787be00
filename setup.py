from glob import glob
import importlib
import os

from setuptools import find_packages, setup

package_name = 'wifi_place_recognition'
console_scripts = [
    'train_model = wifi_place_recognition.cli.train_model:main',
    'evaluate_model = wifi_place_recognition.cli.evaluate_model:main',
    'classifier_node = wifi_place_recognition.ros.executables:classifier_node',
    'replay_scans = wifi_place_recognition.cli.replay_scans:main',
    'fit_tracking = wifi_place_recognition.cli.fit_tracking:main',
    'fit_odometry = wifi_place_recognition.cli.fit_odometry:main',
    'replay_run = wifi_place_recognition.cli.replay_run:main',
    'survey_gaps = wifi_place_recognition.cli.survey_gaps:main',
    'bag_to_csv = wifi_place_recognition.cli.bag_to_csv:main',
    'update_model = wifi_place_recognition.cli.update_model:main',
    'wifi_scanner_node = '
    'wifi_place_recognition.ros.executables:wifi_scanner_node',
    'record_fingerprints = '
    'wifi_place_recognition.ros.executables:record_fingerprints',
    'localization_monitor = '
    'wifi_place_recognition.ros.executables:localization_monitor',
    'trusted_recorder = '
    'wifi_place_recognition.ros.executables:trusted_recorder',
]
# `ros2 run` runs <prefix>/lib/<package>/<executable>. colcon's builds
# (setup.py install / develop) put the console scripts there by setup.cfg;
# a wheel (pip install .) cannot: pip puts them in <prefix>/bin. A wheel can
# only add files under <prefix> as data, copied verbatim, so it gets one
# small shell script per executable in <prefix>/lib/<package> that runs the
# console script in <prefix>/bin. (pip install -e . installs no data files:
# no ros2 run, no share directory.)
WRAPPER = """#!/bin/sh
# ros2 run after a pip install: the console script that pip put in bin.
exec "$(dirname "$0")/../../bin/{name}" "$@"
"""


def ros2_run_wrappers(command):
    """Return a subclass of ``command`` that adds the wrapper scripts."""
    class WithWrappers(command):
        def run(self):
            folder = os.path.join(
                self.get_finalized_command('build').build_base, 'ros2_run')
            os.makedirs(folder, exist_ok=True)
            wrappers = []
            for script in console_scripts:
                name = script.split('=')[0].strip()
                path = os.path.join(folder, name)
                with open(path, 'w') as f:
                    f.write(WRAPPER.format(name=name))
                os.chmod(path, 0o755)
                wrappers.append(path)
            entry = ('lib/' + package_name, wrappers)
            if entry not in self.distribution.data_files:
                self.distribution.data_files.append(entry)
            super().run()
    return WithWrappers


def wheel_command():
    """Return the bdist_wheel class, None where no wheel can be built."""
    # setuptools >= 70.1 has its own; older ones use the wheel package's.
    for module in ('setuptools.command.bdist_wheel', 'wheel.bdist_wheel'):
        try:
            return importlib.import_module(module).bdist_wheel
        except ImportError:
            pass
    return None


bdist_wheel = wheel_command()

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages',
            ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        ('share/' + package_name + '/models', glob('models/*.npz')),
        ('share/' + package_name + '/config', glob('config/*.yaml')),
        ('share/' + package_name + '/launch', glob('launch/*.py')),
    ],
    python_requires='>=3.10',
    install_requires=['setuptools', 'numpy'],
    # The node needs numpy only; torch trains (train_model), scikit-learn
    # runs the benchmark baselines, matplotlib draws evaluate_model --plot,
    # rosbags reads bags in place of CSVs (no ROS install needed);
    # requirements.txt is the development set.
    extras_require={
        'bags': ['rosbags>=0.11'],
        'train': ['torch', 'scikit-learn'],
        'bench': ['torch', 'scikit-learn'],
        'plot': ['matplotlib', 'scikit-learn'],
        'test': ['pytest', 'flake8', 'pydocstyle', 'torch', 'matplotlib',
                 'scikit-learn', 'rosbags>=0.11'],
    },
    zip_safe=True,
    maintainer='wifi_place_recognition developers',
    maintainer_email='dev@wifi-place-recognition.invalid',
    description='Building and floor recognition from one WiFi scan '
                '(SAE + classifier) with a ROS 2 node.',
    license='Apache-2.0',
    entry_points={'console_scripts': console_scripts},
    # colcon builds do not build a wheel: this does not touch them.
    cmdclass={'bdist_wheel': ros2_run_wrappers(bdist_wheel)}
    if bdist_wheel else {},
)
