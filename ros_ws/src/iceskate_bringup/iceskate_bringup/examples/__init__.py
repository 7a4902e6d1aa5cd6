"""Controllers written in Python, as examples of the plug-in interface (docs/usage.md, "Your own
controller"): ``visual_lifting_numpy`` is eq. (9) in a few lines of numpy."""
