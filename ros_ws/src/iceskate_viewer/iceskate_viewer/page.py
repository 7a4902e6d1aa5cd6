"""The 3D page (viser): the ice with a mark every metre, one robot per run side by side, the
support foot highlighted, visual lifting's head target, and time, mode and step as text."""

from __future__ import annotations

from collections.abc import Sequence
import contextlib
import io
import ipaddress

import coal
import numpy as np
import pinocchio as pin
import trimesh
import viser

from iceskate_sim.errors import InputRefused
from iceskate_sim.model.modes import MODES
from iceskate_sim.model.robot import SOLE_HEEL_Y, SOLE_TOE_Y, SOLE_Z
from iceskate_sim.shutdown import say
from iceskate_viewer.front import Front, bind, inner_host
from iceskate_viewer.pose import BodyPose, ViewFrame

#: Lateral distance [m] between two runs' robots.
RUN_SPACING = 1.2
#: The ice drawn: half its width [m], and its length ahead of and behind the start [m].
ICE_HALF_WIDTH, ICE_AHEAD, ICE_BEHIND = 3.0, 40.0, 5.0
#: Colours (RGB 0-255): the ice, its metre marks, the support-foot highlight, the head target.
ICE, MARK, SUPPORT, TARGET = (196, 222, 240), (115, 120, 125), (255, 196, 0), (40, 170, 80)
#: Least move [m] of a following camera (smaller ones wait for the next frame).
FOLLOW_STEP = 0.005
#: The default camera: the height [m] it looks at (mid-body), its bearing from behind the
#: robots (from -y, turned towards +x) and its elevation [rad], its least distance [m] from
#: what it looks at, and the narrowest window (width / height) it frames every run in.
VIEW_HEIGHT, VIEW_BEARING, VIEW_ELEVATION = 0.8, np.radians(30.0), np.radians(15.0)
VIEW_DISTANCE, VIEW_ASPECT = 3.5, 4.0 / 3.0
#: Height [m] and width [m] of what the default camera frames of a robot (with a margin).
ROBOT_HEIGHT, ROBOT_WIDTH = 2.0, 1.6
#: Largest difference [m] between a browser's reported camera and the page's view (up to a
#: move along y) that shows the browser took the page's view.
SAME_VIEW = 1e-3


#: Unit meshes of the URDF's shapes (a box of side 1, a sphere and a cylinder along z of
#: radius 1 and height 1), scaled per link.
UNIT_MESHES = {coal.Box: trimesh.creation.box((1.0, 1.0, 1.0)),
               coal.Sphere: trimesh.creation.icosphere(3, 1.0),
               coal.Cylinder: trimesh.creation.cylinder(1.0, 1.0, sections=24)}


def serve(host: str, port: int) -> PageServer:
    """The page's server on ``host``:``port`` (0: any free port; a busy port: the next free
    one), with a warning when ``host`` is not a loopback address (``PageServer``)."""
    check_port(port)
    check_host(host)
    if not _loopback(host):
        say(f'warning: the view is served on {host}, reachable from other machines '
            '(127.0.0.1 keeps it on this one)')
    server = PageServer(host, port)
    server.gui.configure_theme(show_share_button=False, dark_mode=False)
    return server


class PageServer(viser.ViserServer):
    """A viser server behind a front of ours: viser listens on a free port of a loopback
    address drawn at random (``front.inner_host``), and the page is served on
    ``host``:``port`` by ``Front`` (``iceskate_viewer.front``), which lets in only requests
    that name this server and WebSockets of the page's own origin. ``get_host`` and
    ``get_port`` give the page's address. The page has no share link (it would tunnel the page
    through a server outside this machine): the button is hidden and a request is refused.

    :raises InputRefused: when ``host``:``port`` cannot be served (``bind``).
    :raises SimulationError: when the front does not start.
    """

    def __init__(self, host: str, port: int) -> None:
        sock = bind(host, port)
        inner = inner_host()
        try:
            with contextlib.redirect_stdout(io.StringIO()):  # viser's banner: we print the URL
                super().__init__(host=inner, port=0, verbose=False)
        except BaseException:
            sock.close()
            raise
        try:
            self._page_front = Front(sock, host, inner, super().get_port())
        except BaseException:
            self.stop()
            raise

    def get_host(self) -> str:
        """The host the page is served on."""
        return self._page_front.host

    def get_port(self) -> int:
        """The port the page is served on."""
        return self._page_front.port

    def request_share_url(self, verbose: bool = True) -> None:
        """A share link is never made: the page stays on this machine."""
        del verbose

    def stop(self) -> None:
        """Stop the front (closing every browser's connection), then viser."""
        front = getattr(self, '_page_front', None)
        if front is not None:  # (None: its start failed)
            front.stop()
        super().stop()


def check_port(port: int, what: str = 'port') -> None:
    """Refuse, in one sentence naming ``what``, a port outside 0..65535, before anything is
    served."""
    if not 0 <= port <= 65535:
        raise InputRefused(f'{what} must be 0..65535 (0: any free port), got {port}')


def check_host(host: str) -> None:
    """Refuse, in one sentence, a host this machine cannot serve on, before a run starts
    (``run_scene --view``: its page is served once the run's outputs are taken)."""
    bind(host, 0).close()


def stop_server(server: viser.ViserServer) -> None:
    """Stop ``server`` (quietly)."""
    with contextlib.redirect_stdout(io.StringIO()):
        server.stop()


def url_of(server: viser.ViserServer) -> str:
    """The page's address."""
    host = server.get_host()
    return f'http://{f"[{host}]" if ":" in host else host}:{server.get_port()}'


def _loopback(host: str) -> bool:
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return host == 'localhost'


class RunPage:
    """The scene of ``names`` runs (one robot each, ``RUN_SPACING`` apart along x) on ``server``.

    ``show(k, frame)`` places run ``k``'s robot and overlays; safe from any thread. The page's
    camera (``page_camera``) sees every robot from behind and to the side. While the page's
    **Follow** box is on, every browser's camera target moves along y to the robots (their
    heads' mean y) and its position by the same offset, keeping the angle and distance its
    user chose; until a browser reports the page's view (it reports its own default camera
    first), it is given the page's.
    """

    def __init__(self, server: viser.ViserServer, body: BodyPose, names: Sequence[str]) -> None:
        self.server, self.body = server, body
        scene = server.scene
        # no shadows: a browser without a GPU (software WebGL) draws a frame several times faster
        scene.configure_default_lights(cast_shadow=False)
        scene.configure_environment_map(environment_intensity=0.5)
        length = ICE_AHEAD + ICE_BEHIND
        width = 2 * ICE_HALF_WIDTH + RUN_SPACING * (len(names) - 1)
        centre = (RUN_SPACING * (len(names) - 1) / 2, (ICE_AHEAD - ICE_BEHIND) / 2)
        scene.set_up_direction('+z')
        scene.add_box('/ice', ICE, (width, length, 0.01), position=(*centre, -0.005),
                      cast_shadow=False)
        metres = np.arange(-int(ICE_BEHIND), int(ICE_AHEAD) + 1, dtype=float)
        left, right = centre[0] - width / 2, centre[0] + width / 2
        scene.add_line_segments('/marks', np.array(
            [[[left, y, 0.002], [right, y, 0.002]] for y in metres]), MARK, thickness=0.01)
        for metre in metres[metres >= 0].astype(int):
            scene.add_label(f'/marks/{metre}m', f'{metre} m', position=(0.45, metre, 0.01))
        position, look_at = page_camera(len(names), server.initial_camera.fov)
        server.initial_camera.position, server.initial_camera.look_at = position, look_at
        #: (target, position - target) of the page's camera and of each browser's that took it
        self._page_view = (look_at, position - look_at)
        self._views: dict[int, tuple[np.ndarray, np.ndarray]] = {}
        server.on_client_connect(self._client_connected)
        server.on_client_disconnect(lambda client: self._views.pop(client.client_id, None))
        self.names = tuple(names)
        self._bodies, self._support, self._target, self._labels = [], [], [], []
        for k, name in enumerate(names):
            root = f'/run{k}'
            scene.add_frame(root, show_axes=False, position=(k * RUN_SPACING, 0.0, 0.0))
            self._bodies.append(_Body(scene, f'{root}/robot', body))
            self._support.append(scene.add_box(
                f'{root}/support', SUPPORT, (0.14, SOLE_TOE_Y - SOLE_HEEL_Y + 0.04, 0.004),
                opacity=0.8, cast_shadow=False))
            self._target.append(scene.add_icosphere(f'{root}/head_target', 0.035, TARGET))
            self._labels.append(scene.add_label(f'{root}/name', name))
        self.status = server.gui.add_markdown('')  # a line per run
        self._texts = [''] * len(names)
        self._follow = server.gui.add_checkbox('Follow the robot', True)
        self._head_y = [0.0] * len(names)  # of each run's last frame [m]

    def show(self, k: int, frame: ViewFrame) -> None:
        """Place run ``k``'s robot at ``frame`` (its name above its head), highlight its
        support sole, put its head target (at the head's x) and write its name, time, mode and
        step (the n-th support phase is step n: ``step_index + 1``, as ``coupling_analysis
        --animate`` numbers them)."""
        body = self.body
        body.place(body.configuration(frame))
        foot = body.frame_placement(f'{frame.side}_foot')
        head = body.frame_placement('head_top')
        sole = foot * pin.SE3(np.eye(3), np.array([0.0, (SOLE_TOE_Y + SOLE_HEEL_Y) / 2,
                                                      SOLE_Z - 0.004]))
        mode = MODES[frame.mode]
        self._texts[k] = (f'**{self.names[k]}** · **t = {frame.t:6.3f} s** · mode {frame.mode} '
                          f'({mode.support}/{mode.swing}) · support {frame.side} '
                          f'({frame.pivot}) · step {frame.step_index + 1}')
        with self.server.atomic():
            self._bodies[k].place(body.geometry.oMg)
            self._labels[k].position = head.translation + (0.0, 0.0, 0.12)
            self._support[k].position = sole.translation
            self._support[k].wxyz = _wxyz(sole.rotation)
            target = frame.head_target
            self._target[k].visible = bool(np.all(np.isfinite(target)))
            if self._target[k].visible:
                self._target[k].position = (head.translation[0], target[0], target[1])
            self.status.content = '  \n'.join(self._texts)
        self._head_y[k] = float(head.translation[1])
        if self._follow.value:
            self._follow_robots(float(np.mean(self._head_y)))

    def _follow_robots(self, y: float) -> None:
        """Move each browser's camera target to ``y`` [m] along y (its height and x kept) and
        its position by the same offset (from the target as its user chose it, or as the
        page's camera has it while the browser has not reported the page's view)."""
        for client in self.server.get_clients().values():
            look_at, offset = self._views.get(client.client_id, self._page_view)
            target = np.array([look_at[0], y, look_at[2]])
            camera = client.camera
            if (np.allclose(camera.look_at, target, rtol=0.0, atol=FOLLOW_STEP)
                    and np.allclose(camera.position, target + offset, rtol=0.0,
                                    atol=FOLLOW_STEP)):
                continue
            with camera.client.atomic():
                camera.position = target + offset
                camera.look_at = target

    async def _client_connected(self, client: viser.ClientHandle) -> None:
        """A browser connected: its camera reports (the first one included) are watched."""
        client.camera.on_update(self._camera_reported)

    async def _camera_reported(self, camera: viser.CameraHandle) -> None:
        """A browser reported its camera (in order, on the server's loop): once it has shown
        the page's view, its target and offset are followed from."""
        look_at, offset = np.array(camera.look_at), camera.position - camera.look_at
        client_id = camera.client.client_id
        if client_id in self._views or np.allclose(offset, self._page_view[1], rtol=0.0,
                                                   atol=SAME_VIEW):
            self._views[client_id] = (look_at, offset)


def page_camera(runs: int, fov: float) -> tuple[np.ndarray, np.ndarray]:
    """The page's camera (position, target) [m] for ``runs`` robots side by side at the start
    (``RUN_SPACING`` apart along x): from behind and ``VIEW_BEARING`` to the side, so that no
    robot hides another, at least ``VIEW_DISTANCE`` away and far enough for a window of
    ``VIEW_ASPECT`` at the vertical field of view ``fov`` [rad] to frame them all."""
    spread = RUN_SPACING * (runs - 1) / 2  # from the middle to the outer runs
    look_at = np.array([spread, 0.0, VIEW_HEIGHT])
    half = np.tan(fov / 2)
    across = spread * np.cos(VIEW_BEARING) + ROBOT_WIDTH / 2  # the nearest run: its far side,
    nearer = spread * np.sin(VIEW_BEARING)  # from the view's middle, and the camera
    distance = max(VIEW_DISTANCE, ROBOT_HEIGHT / 2 / half,
                   across / (half * VIEW_ASPECT) + nearer)
    direction = np.array([np.sin(VIEW_BEARING) * np.cos(VIEW_ELEVATION),
                          -np.cos(VIEW_BEARING) * np.cos(VIEW_ELEVATION),
                          np.sin(VIEW_ELEVATION)])
    return look_at + distance * direction, look_at


class _Body:
    """A robot's visual geometry as one batched mesh per shape (boxes, spheres, cylinders):
    three updates a frame, however many links."""

    def __init__(self, scene: viser.SceneApi, root: str, body: BodyPose) -> None:
        groups: dict[type, list[int]] = {}
        for i, item in enumerate(body.visual.geometryObjects):
            groups.setdefault(type(item.geometry), []).append(i)
        self._batches = []
        for kind, indices in groups.items():
            items = [body.visual.geometryObjects[i] for i in indices]
            mesh = UNIT_MESHES[kind]
            self._batches.append((indices, scene.add_batched_meshes_simple(
                f'{root}/{kind.__name__.lower()}', mesh.vertices, mesh.faces,
                np.tile([1.0, 0.0, 0.0, 0.0], (len(items), 1)), np.zeros((len(items), 3)),
                batched_scales=np.array([_scale(item.geometry) for item in items]),
                batched_colors=np.array([np.round(255 * item.meshColor[:3]) for item in items],
                                        dtype=np.uint8), lod='off', cast_shadow=False)))

    def place(self, placements: Sequence[pin.SE3]) -> None:
        """Put every shape at its world placement (``GeometryData.oMg``)."""
        for indices, handle in self._batches:
            handle.batched_positions = np.array([placements[i].translation for i in indices])
            handle.batched_wxyzs = np.array([_wxyz(placements[i].rotation) for i in indices])


def _scale(shape: coal.CollisionGeometry) -> tuple[float, float, float]:
    """The per-axis scale of ``shape``'s unit mesh [m]."""
    if isinstance(shape, coal.Box):
        return tuple(2.0 * shape.halfSide)
    if isinstance(shape, coal.Sphere):
        return (shape.radius,) * 3
    return (shape.radius, shape.radius, 2.0 * shape.halfLength)


def _wxyz(rotation: np.ndarray) -> np.ndarray:
    """A rotation matrix as viser's quaternion (w, x, y, z)."""
    return pin.Quaternion(rotation).coeffs()[[3, 0, 1, 2]]

