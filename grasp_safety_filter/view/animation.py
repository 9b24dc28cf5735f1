"""An animation of a run: a :class:`Frame` per instant, drawn like the pictures, into a GIF.

Each frame is one :func:`~grasp_safety_filter.view.pictures.draw_scene` of the grasp seen
isometrically, with the object's reference pose, the friction cones coloured by the share
used and a line of text (time, the filter's status), inside one box for the whole run so that
the view does not jump. :func:`render_frames` draws frames into palette images (one figure
reused, Agg); :func:`write_gif` writes them, one frame per ``1 / fps`` s of the run, so the
GIF plays in real time. Frames render independently: a caller may split them across cores.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
import io
from pathlib import Path

from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
import numpy as np
from PIL import Image

from grasp_safety_filter.io.files import write_file
from grasp_safety_filter.view.pictures import draw_scene, VIEWS
from grasp_safety_filter.view.scene import GraspScene, Shape

#: Frame size, pixels (width, height), and the GIF's colours per frame.
FRAME_SIZE = (560, 420)
COLOURS = 64


@dataclass(frozen=True)
class Frame:
    """One instant of an animation.

    Attributes:
        scene: The grasp.
        text: Its caption (time, status).
        mu: Friction coefficient per contact, (n,).
        beta: Friction used per contact, ``|f_t| / f_n``, (n,) (inf where ``f_n <= 0``).
        reference: The object's reference pose (None: no reference).
    """

    scene: GraspScene
    text: str
    mu: np.ndarray
    beta: np.ndarray
    reference: Shape | None = None


def render_frames(frames: Sequence[Frame], bounds: np.ndarray) -> list[bytes]:
    """Draw ``frames`` inside the box of ``bounds`` (N, 3), m; return each as a palette PNG."""
    dpi = 80
    figure = Figure(figsize=(FRAME_SIZE[0] / dpi, FRAME_SIZE[1] / dpi), dpi=dpi)
    canvas = FigureCanvasAgg(figure)
    axes = figure.add_axes((0.0, 0.0, 1.0, 0.92), projection='3d')
    caption = figure.text(0.02, 0.96, '', fontsize=9, va='center')
    images = []
    for frame in frames:
        axes.cla()
        draw_scene(
            axes,
            frame.scene,
            bounds=bounds,
            friction=(frame.mu, frame.beta),
            reference=frame.reference,
        )
        axes.view_init(elev=VIEWS[0][1], azim=VIEWS[0][2])
        # No panes, ticks or labels (the palm frame's axes orient the view): the grasp fills
        # the frame, and each frame draws a third faster.
        axes.set_axis_off()
        axes.set_box_aspect((1.0, 1.0, 1.0), zoom=1.5)
        caption.set_text(frame.text)
        canvas.draw()
        rgb = Image.frombuffer('RGBA', canvas.get_width_height(), canvas.buffer_rgba())
        png = io.BytesIO()
        rgb.convert('RGB').quantize(COLOURS).save(png, format='PNG')
        images.append(png.getvalue())
    return images


def write_gif(images: Sequence[bytes], path: Path, fps: float) -> Path:
    """Write the frames' images as a looping GIF at ``fps`` frames per second."""
    frames = [Image.open(io.BytesIO(image)) for image in images]
    gif = io.BytesIO()
    frames[0].save(
        gif,
        format='GIF',
        save_all=True,
        append_images=frames[1:],
        duration=round(1000.0 / fps),
        loop=0,
        optimize=True,
    )
    return write_file(path, gif.getvalue())
