from glob import glob

from setuptools import find_packages, setup

package_name = 'fpr_model'

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
    description=(
        'The Flying Parallel Robot as a ROS-free Python library: parameters, rotations '
        'and frames, geometry, kinematics, dynamics, wrench feasibility.'
    ),
    license='Apache-2.0',
    extras_require={'test': ['pytest']},
    entry_points={
        'console_scripts': [
            'feasibility = fpr_model.feasibility_cli:main',
            'selfcheck = fpr_model.selfcheck:main',
        ],
    },
)
