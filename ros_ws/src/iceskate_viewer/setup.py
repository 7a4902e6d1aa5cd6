from setuptools import find_packages, setup

package_name = 'iceskate_viewer'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test', 'test.*']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
    ],
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='iceskate developers',
    maintainer_email='iceskate@example.com',
    description='The robot in 3D in the browser: a live view of a run and a replay view.',
    license='Apache-2.0',
    extras_require={'test': ['pytest']},
    entry_points={'console_scripts': ['view = iceskate_viewer.replay:main']},
)
