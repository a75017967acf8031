from glob import glob

from setuptools import find_packages, setup

package_name = 'fpr_px4_bridge'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        ('share/' + package_name + '/config', glob('config/*.yaml')),
    ],
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='fpr maintainers',
    maintainer_email='fpr-maintainers@example.org',
    description='MAVLink 2 offboard attitude/thrust bridge between the FPR controller and a PX4 autopilot.',
    license='Apache-2.0',
    extras_require={'test': ['pytest']},
    entry_points={
        'console_scripts': [
            'px4_bridge = fpr_px4_bridge.px4_bridge_node:main',
        ],
    },
)
