from glob import glob
import os

from setuptools import find_packages, setup

package_name = 'iceskate_bringup'


def share_tree(folder):
    """Return data_files entries installing every file under folder to share/<pkg>/<folder>.

    Sub-folders are kept. A missing or empty folder gives no entry.
    """
    entries = {}
    for path in sorted(glob(os.path.join(folder, '**', '*'), recursive=True)):
        if os.path.isfile(path) and '__pycache__' not in path.split(os.sep):
            dest = os.path.join('share', package_name, os.path.dirname(path))
            entries.setdefault(dest, []).append(path)
    return list(entries.items())


data_files = [
    ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
    # it ships scenes (iceskate_sim.run.scene.SCENE_RESOURCE): share/<pkg>/scenes/<name>.yaml
    ('share/ament_index/resource_index/iceskate_scenes', ['resource/' + package_name]),
    ('share/' + package_name, ['package.xml']),
]
for folder in ('scenes', 'launch', 'config'):
    data_files += share_tree(folder)

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test', 'test.*']),
    data_files=data_files,
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='iceskate developers',
    maintainer_email='iceskate@example.com',
    description=(
        'Bringup of the iceskate stack: scenes, their composition into node parameters, the '
        'headless runner run_scene and the three-node ROS graph.'
    ),
    license='Apache-2.0',
    extras_require={'test': ['pytest']},
    entry_points={
        'console_scripts': [
            'run_scene = iceskate_bringup.runner:main',
            'plugin_controller = iceskate_bringup.plugin_node:main',
        ],
    },
)
