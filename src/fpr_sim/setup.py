from glob import glob

from setuptools import find_packages, setup

package_name = 'fpr_sim'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        ('share/' + package_name + '/config', glob('config/*.yaml')),
        ('share/' + package_name + '/config/scenarios', glob('config/scenarios/*.yaml')),
    ],
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='fpr maintainers',
    maintainer_email='fpr-maintainers@example.org',
    description=(
        'Simulator node replacing the FPR hardware: plant, PX4 autopilot emulators over '
        'MAVLink 2, cameras.'
    ),
    license='Apache-2.0',
    extras_require={'test': ['pytest']},
    entry_points={
        'console_scripts': [
            'simulator = fpr_sim.simulator:main',
        ],
    },
)
