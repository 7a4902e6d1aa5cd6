from glob import glob

from setuptools import find_packages, setup

package_name = 'iceskate_study'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test', 'test.*']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        # it ships studies (iceskate_study.spec.STUDY_RESOURCE): share/<pkg>/studies/<name>.yaml
        ('share/ament_index/resource_index/iceskate_studies', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        ('share/' + package_name + '/studies', sorted(glob('studies/*.yaml'))),
    ],
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='iceskate developers',
    maintainer_email='iceskate@example.com',
    description=('Parameter studies of iceskate scenes: sweep (local processes or a Ray '
                 'cluster, one resumable Parquet table) and sweep-plot (heat maps of the '
                 'metrics).'),
    license='Apache-2.0',
    extras_require={'test': ['pytest']},
    entry_points={'console_scripts': ['sweep = iceskate_study.sweep:main',
                                      'sweep-plot = iceskate_study.plot:main']},
)
