"""The robot in 3D in the browser (viser): a live view of a run and a replay view."""
