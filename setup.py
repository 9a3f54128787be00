from glob import glob

from setuptools import find_packages, setup

package_name = 'wifi_place_recognition'

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
    # runs the benchmark baselines, matplotlib draws evaluate_model --plot;
    # requirements.txt is the development set.
    extras_require={
        'train': ['torch'],
        'bench': ['torch', 'scikit-learn'],
        'plot': ['matplotlib', 'scikit-learn'],
        'test': ['pytest', 'flake8', 'pydocstyle', 'torch', 'matplotlib',
                 'scikit-learn'],
    },
    zip_safe=True,
    maintainer='wifi_place_recognition developers',
    maintainer_email='dev@wifi-place-recognition.invalid',
    description='Building and floor recognition from one WiFi scan '
                '(SAE + classifier) with a ROS 2 node.',
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            'train_model = wifi_place_recognition.cli.train_model:main',
            'evaluate_model = wifi_place_recognition.cli.evaluate_model:main',
            'classifier_node = '
            'wifi_place_recognition.ros.executables:classifier_node',
            'replay_scans = wifi_place_recognition.cli.replay_scans:main',
            'fit_tracking = wifi_place_recognition.cli.fit_tracking:main',
            'wifi_scanner_node = '
            'wifi_place_recognition.ros.executables:wifi_scanner_node',
            'record_fingerprints = '
            'wifi_place_recognition.ros.executables:record_fingerprints',
        ],
    },
)
