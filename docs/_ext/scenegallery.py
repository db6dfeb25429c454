"""The gallery's image scraper: shows the figures a scene run drew, as the scene drew them.

A gallery example runs a shipped scene with :func:`fpe_harvester.run_scene`, which writes its
figures as PNG files (``SceneResult.figures``). Re-plotting them would duplicate the scenes'
plotting code; this scraper copies each new figure of any ``SceneResult`` in the example's
namespace into the gallery, at the resolution the scene drew it.
"""

from __future__ import annotations

import shutil
from pathlib import Path
from typing import Any

from sphinx_gallery.scrapers import figure_rst

from fpe_harvester import SceneResult


def scene_scraper(block: Any, block_vars: dict[str, Any], gallery_conf: dict[str, Any]) -> str:
    """reStructuredText showing the figures drawn by the scene runs of one code block.

    Parameters
    ----------
    block : tuple
        The code block (sphinx-gallery's ``(label, content, line)``); unused.
    block_vars : dict
        sphinx-gallery's variables of the example: ``example_globals`` (the namespace) and
        ``image_path_iterator`` (where the gallery wants each image).
    gallery_conf : dict
        sphinx-gallery's configuration (``src_dir``).

    Returns
    -------
    str
        The reStructuredText of the images, empty when the block drew none.
    """
    shown: set[str] = block_vars.setdefault("scene_figures_shown", set())
    images = []
    for value in list(block_vars["example_globals"].values()):
        if not isinstance(value, SceneResult):
            continue
        for path in value.figures.values():
            if str(path) in shown:
                continue
            shown.add(str(path))
            target = Path(next(block_vars["image_path_iterator"]))
            shutil.copyfile(path, target)
            images.append(target)
    return figure_rst(images, gallery_conf["src_dir"]) if images else ""
