"""Genesis's ``scene.visualizer`` without a viewer: what its calls mean headless here.

Genesis's visualizer keeps what its renderers drew and syncs it with the scene on a step or on
``update()``; here every ``camera.render()`` draws the scene's current state (and moves an attached
or following camera first), so there is nothing to sync, and ``update`` (Genesis's headless scripts
call it after moving a robot by setters) only checks its arguments."""
from ..options import check_bool


class Visualizer:
    """``scene.visualizer``: ``update``, ``cameras``, ``viewer`` (None: no interactive viewer)."""

    def __init__(self, scene):
        self._scene = scene

    def update(self, force=True, auto=None):
        """Genesis's sync of its renderers and viewer with the scene: nothing to do here (see the
        module docstring); force a bool, auto None or a bool (the viewer's)."""
        check_bool("scene.visualizer.update", "force", force)
        if auto is not None:
            check_bool("scene.visualizer.update", "auto", auto)

    @property
    def cameras(self):
        """The scene's cameras, in the order added."""
        return list(self._scene._cameras)

    @property
    def viewer(self):
        """None: there is no interactive viewer."""
        return None

    def __getattr__(self, name):
        if name.startswith("_"):
            raise AttributeError(name)
        raise AttributeError(f"scene.visualizer has no '{name}': without a viewer it offers update(), cameras and "
                             f"viewer (None); draw with the cameras (scene.add_camera, camera.render)")
