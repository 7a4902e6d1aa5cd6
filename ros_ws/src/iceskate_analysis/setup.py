from setuptools import find_packages, setup

package_name = 'iceskate_analysis'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test', 'test.*']),
    data_files=[('share/ament_index/resource_index/packages', ['resource/' + package_name]),
                ('share/' + package_name, ['package.xml'])],
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='iceskate developers',
    maintainer_email='iceskate@example.com',
    description=('Offline analysis of iceskate bags (the eq. (11) coupling analysis, plots, '
                 'animation, run summaries) and bag replay.'),
    license='Apache-2.0',
    extras_require={'test': ['pytest']},
    entry_points={'console_scripts': ['coupling_analysis = iceskate_analysis.coupling_cli:main',
                                      'mode_coverage = iceskate_analysis.coverage_cli:main',
                                      'replay = iceskate_analysis.replay:main',
                                      'summary = iceskate_analysis.summary:main']},
)
