from glob import glob

from setuptools import find_packages, setup

package_name = 'fpr_control'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        ('share/' + package_name + '/config', glob('config/*.yaml')),
        ('share/' + package_name + '/config/joy_scripts', glob('config/joy_scripts/*.yaml')),
    ],
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='fpr maintainers',
    maintainer_email='fpr-maintainers@example.org',
    description='Decentralized FPR controllers (C, NC, impedance) with wrench observers, '
                'and the ground teleoperation path.',
    license='Apache-2.0',
    extras_require={'test': ['pytest']},
    entry_points={
        'console_scripts': [
            'controller = fpr_control.controller_node:main',
            'teleop = fpr_control.teleop_node:main',
            'joystick = fpr_control.joystick_node:main',
            'joy_script = fpr_control.joy_script_node:main',
        ],
    },
)
