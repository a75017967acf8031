import hashlib
import os
import shutil
from glob import glob

from setuptools import Extension, find_packages, setup
from setuptools.command.build_ext import build_ext

package_name = 'fpr_sim'

# Optional compiled plant kernel (plain C99, no Python C-API, loaded with ctypes by fpr_sim._kernels). Built by
# `colcon build` (setup.py build/install) and `colcon build --symlink-install` (setup.py develop -> build_ext
# --inplace) whenever a C compiler exists; without one the package installs anyway and fpr_sim runs its
# pure-Python plant (one INFO log line says so). The source's SHA-256 is compiled in so that a library older
# than plant_kernel.c is detected (and not used) at run time.
KERNEL_SOURCE = os.path.join('fpr_sim', '_kernels', 'plant_kernel.c')


def _kernel_source_hash() -> str:
    here = os.path.dirname(os.path.abspath(__file__))
    try:
        with open(os.path.join(here, KERNEL_SOURCE), 'rb') as source:
            return hashlib.sha256(source.read()).hexdigest()
    except OSError:
        return 'unknown'


class OptionalBuildExt(build_ext):
    """build_ext that never fails the package build: a missing compiler or a compile error is a warning."""

    def build_extensions(self):
        if self.compiler.compiler_type == 'unix':
            for ext in self.extensions:
                # C99; no FMA contraction, no fast-math: the kernel must round like the Python reference
                ext.extra_compile_args = ['-std=c99', '-O2', '-ffp-contract=off', '-fno-fast-math']
                ext.libraries = ['m']
        super().build_extensions()

    def run(self):
        try:
            super().run()
        except Exception as error:  # noqa: BLE001 - any build failure only disables the optional kernel
            self.warn(f'fpr_sim: optional compiled plant kernel not built ({error}); the pure-Python plant '
                      'will be used')

    def build_extension(self, ext):
        try:
            super().build_extension(ext)
        except Exception as error:  # noqa: BLE001
            self.warn(f'fpr_sim: optional compiled plant kernel not built ({error}); the pure-Python plant '
                      'will be used')

    def copy_file(self, infile, outfile, *args, **kwargs):
        """In-place (develop / symlink-install) copies replace the library atomically: a running process
        that has the old one mapped keeps its inode instead of seeing it truncated."""
        if self.dry_run or not str(outfile).endswith(('.so', '.pyd', '.dylib')):
            return super().copy_file(infile, outfile, *args, **kwargs)
        temporary = f'{outfile}.tmp{os.getpid()}'
        shutil.copyfile(infile, temporary)
        shutil.copymode(infile, temporary)
        os.replace(temporary, outfile)
        return outfile, 1


setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    ext_modules=[Extension(
        'fpr_sim._kernels._fpr_plant_kernel', sources=[KERNEL_SOURCE], optional=True,
        define_macros=[('FPR_KERNEL_SOURCE_HASH', f'"{_kernel_source_hash()}"')])],
    cmdclass={'build_ext': OptionalBuildExt},
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        ('share/' + package_name + '/config', glob('config/*.yaml')),
        ('share/' + package_name + '/config/scenarios', glob('config/scenarios/*.yaml')),
        # realism profiles: one directory each (config/realism/<profile>/*.yaml, fpr_sim.scenario.realism_overlay)
        *[('share/' + package_name + '/' + d, glob(d + '/*.yaml')) for d in sorted(glob('config/realism/*'))],
    ],
    install_requires=['setuptools'],
    zip_safe=False,  # the compiled kernel is loaded from a file
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
