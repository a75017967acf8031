from glob import glob

from setuptools import find_packages, setup

package_name = 'fpr_estimation'

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
    description='On-board ArUco marker detection, relative-pose EKF and FPR state reconstruction.',
    license='Apache-2.0',
    extras_require={'test': ['pytest']},
    entry_points={
        'console_scripts': [
            'aruco_detector = fpr_estimation.aruco_detector:main',
            'pose_estimator = fpr_estimation.pose_estimator:main',
        ],
    },
)
