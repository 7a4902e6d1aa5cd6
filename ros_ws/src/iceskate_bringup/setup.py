from glob import glob

from setuptools import find_packages, setup

package_name = 'iceskate_bringup'

data_files = [
    ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
    # it ships scenes (iceskate_sim.run.scene.SCENE_RESOURCE): share/<pkg>/scenes/<name>.yaml
    ('share/ament_index/resource_index/iceskate_scenes', ['resource/' + package_name]),
    ('share/' + package_name, ['package.xml']),
]
for folder, pattern in (('scenes', '*.yaml'), ('launch', '*.py'), ('config', '*.yaml')):
    data_files.append((f'share/{package_name}/{folder}', sorted(glob(f'{folder}/{pattern}'))))

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test', 'test.*']),
    data_files=data_files,
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='iceskate developers',
    maintainer_email='iceskate@example.com',
    description=('Bringup of the iceskate stack: scenes, their composition into node '
                 'parameters, the headless runner run_scene and the three-node ROS graph.'),
    license='Apache-2.0',
    extras_require={'test': ['pytest']},
    entry_points={'console_scripts': ['run_scene = iceskate_bringup.runner:main',
                                      'plugin_controller = iceskate_bringup.plugin_node:main']},
)
