"""Mesh pictures: files are written atomically, deformed meshes and per-vertex colours draw."""

import numpy as np
import pytest
from PIL import Image

from lipgen.mesh.plot import plot_mesh, render_default_lips
from lipgen.mesh.procedural import lip_mesh


def test_default_picture(tmp_path):
    path = render_default_lips(tmp_path, resolution=0)
    with Image.open(path) as im:
        assert im.size[0] > 1000 and im.size[1] > 400
        px = np.asarray(im.convert("RGB"), float)
    assert px.std() > 20  # something was drawn


def test_deformed_with_values(tmp_path):
    m = lip_mesh(0)
    U = np.zeros_like(m.vertices)
    U[:, 1] = -0.2 * m.vertices[:, 0]
    fig = plot_mesh(m, tmp_path / "d.png", views=("front", (30.0, 10.0)), vertices=m.vertices + U,
                    values=np.linalg.norm(U, axis=1), value_label="|U| (mm)")
    assert (tmp_path / "d.png").stat().st_size > 10_000 and len(fig.axes) == 3  # 2 panels + colour bar
    with pytest.raises(ValueError, match="values must have shape"):
        plot_mesh(m, values=np.zeros(3))
    with pytest.raises(ValueError, match="unknown view"):
        plot_mesh(m, views=("top",))
