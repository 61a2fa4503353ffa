"""Image scraper of the gallery: the figures pwsdyn's plotting functions return.

They are :class:`matplotlib.figure.Figure` objects that pyplot does not manage (so that any
program can draw into them without a display), which sphinx-gallery's matplotlib scraper
never sees: an example that ends a block with ``fig`` would show no figure.
"""

from __future__ import annotations

_SCRAPED: dict = {}


def pwsdyn_figures(block, block_vars, gallery_conf, **kwargs):
    """Each Figure the example holds in a variable, saved once, after the block that made it
    (figures made through pyplot are the matplotlib scraper's)."""
    from matplotlib.figure import Figure
    from sphinx_gallery.scrapers import figure_rst

    seen = _SCRAPED.setdefault(str(block_vars["src_file"]), set())
    paths = []
    for value in list(block_vars["example_globals"].values()):
        # pyplot numbers the figures it makes (and keeps the number after closing them)
        if (isinstance(value, Figure) and id(value) not in seen
                and getattr(value, "_number", None) is None):
            seen.add(id(value))
            path = next(block_vars["image_path_iterator"])
            value.savefig(path, dpi=100)
            paths.append(path)
    return figure_rst(paths, gallery_conf["src_dir"])
