from glob import glob

from setuptools import find_packages, setup

package_name = 'fpr_experiments'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        ('share/' + package_name + '/launch', glob('launch/*.py')),
        ('share/' + package_name + '/config/experiments', glob('config/experiments/*.yaml')),
        ('share/' + package_name + '/config/scenarios', glob('config/scenarios/*.yaml')),
        ('share/' + package_name + '/config/joy_scripts', glob('config/joy_scripts/*.yaml')),
        ('share/' + package_name + '/config/models', glob('config/models/*.yaml')),
        ('share/' + package_name + '/config/mappings', glob('config/mappings/*.yaml')),
        ('share/' + package_name + '/config/thesis', glob('config/thesis/*.yaml')),
        ('share/' + package_name + '/config/calibration', glob('config/calibration/*.yaml')),
        ('share/' + package_name + '/config/viz', glob('config/viz/*')),
        ('share/' + package_name + '/config/sros2', glob('config/sros2/*')),
    ],
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='fpr maintainers',
    maintainer_email='fpr-maintainers@example.org',
    description='The FPR node graph description and the thesis experiments as a runnable suite.',
    license='Apache-2.0',
    extras_require={'test': ['pytest']},
    entry_points={
        'console_scripts': [
            'run = fpr_experiments.cli:run_main',
            'list = fpr_experiments.cli:list_main',
            'node_group = fpr_experiments.node_group:main',
            'pilot = fpr_experiments.pilot_node:main',
            'info_link = fpr_experiments.info_link_node:main',
            'detection_fallback = fpr_experiments.detection_fallback_node:main',
            'calibrate = fpr_experiments.calibration:main',
            'spread = fpr_experiments.spread:main',
            'margin = fpr_experiments.margin:main',
            'compare_runs = fpr_experiments.compare_runs:main',
            'faults = fpr_experiments.faults:main',
            'security_policy = fpr_experiments.security:main',
        ],
    },
)
