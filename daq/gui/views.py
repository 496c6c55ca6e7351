"""The live views (pyqtgraph): trace + drive, spectrum, spatial-frequency map, quasi-band
diagram, amplitude-sweep map. Each view takes plain arrays from :mod:`daq.gui.live_data`;
none touches instruments. Traces are min/max decimated (:mod:`daq.gui.decimate`)."""

from __future__ import annotations

from typing import Any

import numpy as np
import pyqtgraph as pg
from numpy.typing import NDArray
from PySide6.QtWidgets import QCheckBox, QComboBox, QHBoxLayout, QTabWidget, QWidget

from analysis.display import amplitude_scale
from daq.gui import refcount_guard
from daq.gui.decimate import minmax_decimate
from daq.gui.live_data import LiveData, ScanView, Trace
from protocols.runfile import ChainInfo

__all__ = [
    "BandView",
    "LiveViews",
    "SpatialMapView",
    "SpectrumView",
    "SweepView",
    "TraceView",
]

pg.setConfigOptions(antialias=False, background="w", foreground="k")

_CMAP = pg.colormap.get("viridis")
_BAND_BRUSH = (255, 160, 0, 60)
_INPUT_PEN = pg.mkPen((220, 0, 0), width=2, style=pg.QtCore.Qt.PenStyle.DashLine)
_EDGE_PEN = pg.mkPen((255, 140, 0), width=2)
#: failed points on the maps (a cross: the input line is red too, but a line)
_FAILED_RGB = (255, 60, 60)


def _failed_marks(plot: pg.PlotWidget) -> pg.ScatterPlotItem:
    """The red crosses of the failed points on ``plot``, above its image."""
    marks = pg.ScatterPlotItem(symbol="x", size=14, pen=pg.mkPen(_FAILED_RGB, width=3), brush=None)
    marks.setZValue(11)
    plot.addItem(marks)
    return marks


def amplitude_scale_text(values: Any, units: str) -> tuple[float, str]:
    """``(factor, unit)`` to show drive amplitudes in ``units`` (a run file's, a plan's): the
    generator's volts as Vpp, a displacement (m) or a force (N) with a readable prefix
    (:func:`analysis.display.amplitude_scale`, "u" for micro as the window writes it). Before,
    every unit but m read Vpp: a 12 N force run was labelled 12 Vpp. A file that names no
    unit ("": before units were stored) is read as the generator's, as it was."""
    if units in ("V", ""):  # the generator's peak-to-peak volts
        return 1.0, "Vpp"
    factor, unit = amplitude_scale(values, units)
    return factor, unit.replace("µ", "u")


def amplitude_text(amplitude: float, units: str) -> str:
    """A drive amplitude with its unit, e.g. ``2e-6, "m"`` -> ``"2 um"``, ``12, "N"`` ->
    ``"12 N"``, ``1, "V"`` -> ``"1 Vpp"``; ``"-"`` for an amplitude that is not a number."""
    if not np.isfinite(amplitude):
        return "-"
    factor, unit = amplitude_scale_text([amplitude], units)
    return f"{amplitude / factor:.3g} {unit}".rstrip()


_MODEL_PEN = pg.mkPen((0, 0, 0), width=1.5, style=pg.QtCore.Qt.PenStyle.DashLine)


def _band_arrays(chain: ChainInfo | None) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    if chain is None:
        return np.zeros((0, 0)), np.zeros((0, 0))
    return np.atleast_2d(chain.onset_Hz).astype(float), np.atleast_2d(chain.cutoff_Hz).astype(float)


class TraceView(pg.GraphicsLayoutWidget):
    """The last velocity record (mm/s) above its drive (normalised), time in ms, x linked."""

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.p_vel = self.addPlot(row=0, col=0)
        self.p_vel.setLabel("left", "velocity", units="mm/s")
        self.p_vel.showGrid(x=True, y=True, alpha=0.3)
        self.p_drv = self.addPlot(row=1, col=0)
        self.p_drv.setLabel("left", "drive (norm.)")
        self.p_drv.setLabel("bottom", "time since trigger", units="ms")
        self.p_drv.setXLink(self.p_vel)
        self.p_drv.showGrid(x=True, y=True, alpha=0.3)
        self.ci.layout.setRowStretchFactor(0, 3)
        self.ci.layout.setRowStretchFactor(1, 1)
        self.c_vel = self.p_vel.plot(pen=pg.mkPen((20, 60, 200), width=1))
        self.c_drv = self.p_drv.plot(pen=pg.mkPen((200, 40, 40), width=1))
        for p in (self.p_vel, self.p_drv):
            p.getAxis("left").enableAutoSIPrefix(False)
            p.getAxis("bottom").enableAutoSIPrefix(False)
            p.getAxis("left").setWidth(60)
        self.n_drawn = 0

    def show_trace(self, tr: Trace) -> None:
        t_ms = tr.time_s * 1e3
        x, y = minmax_decimate(t_ms, tr.velocity_m_per_s * 1e3)
        self.c_vel.setData(x, y)
        xd, yd = minmax_decimate(t_ms, tr.drive)
        self.c_drv.setData(xd, yd)
        self.p_drv.setLabel("left", f"drive ({tr.drive_units})")
        amp = amplitude_text(tr.amplitude, tr.amplitude_units)
        self.p_vel.setTitle(f"{tr.direction}  amplitude {amp}  cylinder {tr.cylinder}")
        self.n_drawn = int(x.size)


class SpectrumView(pg.PlotWidget):
    """The last record's spectrum (log magnitude) with the input frequency and the quasi-band
    edges of the measured cylinder marked."""

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.setLabel("bottom", "frequency (kHz)")
        self.setLabel("left", "|V(f)| (m)")
        self.setLogMode(y=True)
        self.getAxis("left").enableAutoSIPrefix(False)
        self.showGrid(x=True, y=True, alpha=0.3)
        self.curve = self.plot(pen=pg.mkPen((20, 60, 200), width=1.5))
        self.input_line = pg.InfiniteLine(
            angle=90,
            pen=_INPUT_PEN,
            label="f_in",
            labelOpts={"color": (200, 0, 0), "position": 0.92},
        )
        self.addItem(self.input_line)
        self.band = pg.LinearRegionItem(brush=_BAND_BRUSH, movable=False)
        self.band.setZValue(-10)
        self.addItem(self.band)
        self.band.hide()
        self.getPlotItem().addLegend(offset=(-10, 10))
        self.model_curve = self.plot(pen=_MODEL_PEN, name="model")
        self.model_curve.hide()
        self.n_drawn = 0

    def show_model(
        self, freq_Hz: NDArray[np.float64] | None, mag: NDArray[np.float64] | None
    ) -> None:
        """The model's spectrum of the point (dashed), or hide it (``None``)."""
        if freq_Hz is None or mag is None:
            self.model_curve.hide()
            return
        m = np.where(mag > 0, mag, np.nan)
        self.model_curve.setData(freq_Hz / 1e3, m)
        self.model_curve.show()

    def show_spectrum(self, tr: Trace, f_in_Hz: float, chain: ChainInfo | None) -> None:
        mag = np.where(tr.magnitude > 0, tr.magnitude, np.nan)
        self.curve.setData(tr.freq_Hz / 1e3, mag)
        self.input_line.setValue(f_in_Hz / 1e3)
        onset, cutoff = _band_arrays(chain)
        i = tr.cylinder - 1
        if onset.size and 0 <= i < onset.shape[0]:
            b = _resonance_band(onset, cutoff)
            self.band.setRegion((onset[i, b] / 1e3, cutoff[i, b] / 1e3))
            self.band.show()
        self.setTitle(
            f"spectrum: {tr.direction}, "
            f"amplitude {amplitude_text(tr.amplitude, tr.amplitude_units)}"
            f", cylinder {tr.cylinder} (band shaded)"
        )
        self.n_drawn = int(np.count_nonzero(np.isfinite(mag)))


def _resonance_band(onset: NDArray[np.float64], cutoff: NDArray[np.float64]) -> int:
    for b in range(onset.shape[1]):
        o, c = onset[:, b], cutoff[:, b]
        if np.all(np.isfinite(o)) and np.all(o > 0) and np.all(c > o):
            return b
    return 0


class SpatialMapView(pg.PlotWidget):
    """Spatial-frequency map: cylinder (y) vs frequency (x), colour = log10 |V(f)|, filling in
    cylinder by cylinder; band edges of the chain and the input frequency overlaid."""

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.setLabel("bottom", "frequency (kHz)")
        self.setLabel("left", "cylinder")
        self.image = pg.ImageItem(axisOrder="row-major")
        self.image.setColorMap(_CMAP)
        self.addItem(self.image)
        self.colorbar = pg.ColorBarItem(colorMap=_CMAP, label="log10 |V(f)| (m)", interactive=False)
        self.colorbar.setImageItem(self.image, insert_in=self.getPlotItem())
        self.input_line = pg.InfiniteLine(angle=90, pen=_INPUT_PEN)
        self.addItem(self.input_line)
        self.onset_curve = self.plot(pen=_EDGE_PEN)
        self.cutoff_curve = self.plot(pen=_EDGE_PEN)
        self.model_peaks = pg.ScatterPlotItem(
            symbol="x", size=10, pen=pg.mkPen((255, 255, 255), width=2), brush=None
        )
        self.model_peaks.setZValue(10)
        self.addItem(self.model_peaks)
        self.model_peaks.hide()
        self.failed_marks = _failed_marks(self)
        self.n_rows = 0
        self.n_failed = 0

    def show_model_peaks(self, peak_Hz: NDArray[np.float64] | None) -> None:
        """The model's peak frequency of every cylinder (white crosses), or hide (``None``)."""
        if peak_Hz is None:
            self.model_peaks.hide()
            return
        n = np.arange(1, peak_Hz.size + 1, dtype=float)
        ok = np.isfinite(peak_Hz)
        self.model_peaks.setData(peak_Hz[ok] / 1e3, n[ok])
        self.model_peaks.show()

    def show_map(self, scan: ScanView, ai: int, chain: ChainInfo | None) -> None:
        mag = scan.spectrum[ai]  # [C, F]
        with np.errstate(divide="ignore", invalid="ignore"):
            img = np.log10(mag)
        finite = np.isfinite(img)
        self.n_rows = int(np.count_nonzero(finite.any(axis=1)))
        failed = scan.failed[ai]
        self.n_failed = int(np.count_nonzero(failed))
        if not finite.any() or scan.freq_Hz.size < 2:
            self.image.clear()
            x0 = float(scan.freq_Hz[0]) / 1e3 if scan.freq_Hz.size else 0.0
            self.failed_marks.setData(  # every cylinder of this amplitude failed: still shown
                np.full(self.n_failed, x0), scan.cylinders[failed].astype(float)
            )
            self._title(scan, ai)  # not the previous amplitude's title
            return
        lo, hi = np.percentile(img[finite], [5, 100])
        # not measured (or failed): NaN, drawn transparent, outside the colour scale; it was
        # set below the scale and clipped to its lowest colour, as a quiet measured cell
        img = np.where(finite, img, np.nan)
        # one row per cylinder number 1..n, so the rows line up with the band edges drawn per
        # cylinder; a cylinder not scanned is empty (it took its nearest scanned neighbour's
        # spectrum, as if measured: the figures' maps leave such gaps too)
        cyl = np.sort(scan.cylinders)
        onset, cutoff = _band_arrays(chain)
        n_rows = int(max(int(cyl[-1]), onset.shape[0] if onset.size else 0))
        grid = np.full((n_rows, img.shape[1]), np.nan)
        grid[scan.cylinders.astype(int) - 1] = img
        f_khz = scan.freq_Hz / 1e3
        self.image.setImage(grid, levels=(lo, hi))
        self.colorbar.setLevels((lo, hi))
        self.image.setRect(pg.QtCore.QRectF(f_khz[0], 0.5, f_khz[-1] - f_khz[0], n_rows))
        if len(cyl) <= 12:
            self.getAxis("left").setTicks([[(int(c), str(int(c))) for c in cyl]])
        else:
            self.getAxis("left").setTicks(None)
        self.input_line.setValue(scan.f_center_Hz / 1e3)
        if onset.size:
            b = _resonance_band(onset, cutoff)
            n = np.arange(1, onset.shape[0] + 1)
            self.onset_curve.setData(onset[:, b] / 1e3, n)
            self.cutoff_curve.setData(cutoff[:, b] / 1e3, n)
        x_mark = f_khz[0] + 0.03 * (f_khz[-1] - f_khz[0])
        self.failed_marks.setData(
            np.full(self.n_failed, x_mark), scan.cylinders[failed].astype(float)
        )
        self._title(scan, ai)
        self.setXRange(f_khz[0], f_khz[-1], padding=0)
        self.setYRange(0.5, n_rows + 0.5, padding=0)

    def _title(self, scan: ScanView, ai: int) -> None:
        """Direction, amplitude ``ai``, cylinders measured and failed."""
        failed = f", {self.n_failed} failed: red x" if self.n_failed else ""
        self.setTitle(
            f"spatial-frequency map: {scan.direction}, "
            f"{amplitude_text(float(scan.amplitudes[ai]), scan.amplitude_units)} "
            f"({self.n_rows}/{len(scan.cylinders)} cylinders{failed})"
        )


class BandView(pg.PlotWidget):
    """Quasi-band diagram of the bench's chain: each band's onset..cutoff per cylinder."""

    COLOURS = ((255, 160, 0, 90), (60, 160, 60, 90), (60, 90, 220, 90), (160, 60, 160, 90))

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.setLabel("bottom", "cylinder")
        self.setLabel("left", "frequency (kHz)")
        self.showGrid(x=True, y=True, alpha=0.3)
        self.setTitle("quasi-band diagram of the chain")
        self.input_line = pg.InfiniteLine(
            angle=0,
            pen=_INPUT_PEN,
            label="f_in",
            labelOpts={"color": (200, 0, 0), "position": 0.95},
        )
        self.n_bands = 0
        self._items: list[object] = []

    def set_input(self, f_in_Hz: float) -> None:
        """Move the input line to ``f_in_Hz`` (the direction being measured: it stayed at the
        first direction's 8.92 kHz through an rtl scan)."""
        self.input_line.setValue(f_in_Hz / 1e3)
        if self.input_line not in self._items:
            self.addItem(self.input_line)
            self._items.append(self.input_line)

    def show_chain(self, chain: ChainInfo | None, f_in_Hz: float | None = None) -> None:
        for it in self._items:
            self.removeItem(it)
        self._items = []
        onset, cutoff = _band_arrays(chain)
        n = np.arange(1, onset.shape[0] + 1, dtype=float)
        self.n_bands = int(onset.shape[1]) if onset.size else 0
        for b in range(self.n_bands):
            col = self.COLOURS[b % len(self.COLOURS)]
            lo = self.plot(n, onset[:, b] / 1e3, pen=pg.mkPen(col[:3], width=1.5))
            hi = self.plot(n, cutoff[:, b] / 1e3, pen=pg.mkPen(col[:3], width=1.5))
            fill = pg.FillBetweenItem(lo, hi, brush=col)
            self.addItem(fill)
            self._items += [lo, hi, fill]
        if f_in_Hz is not None:
            self.input_line.setValue(f_in_Hz / 1e3)
            self.addItem(self.input_line)
            self._items.append(self.input_line)


class SweepView(pg.PlotWidget):
    """Amplitude-sweep map: cylinder (x) vs drive amplitude (y), colour = |V(f_in)| normalised
    per amplitude (how far the input frequency travels at each amplitude)."""

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.setLabel("bottom", "cylinder")
        self.setLabel("left", "amplitude index")
        for side in ("left", "bottom"):  # one amplitude read "amplitude (x0.001)"
            self.getAxis(side).enableAutoSIPrefix(False)
        self.image = pg.ImageItem(axisOrder="row-major")
        self.image.setColorMap(_CMAP)
        self.addItem(self.image)
        self.colorbar = pg.ColorBarItem(
            colorMap=_CMAP, label="log10 of |V(f_in)| / row max", interactive=False
        )
        self.colorbar.setImageItem(self.image, insert_in=self.getPlotItem())
        self.setTitle("amplitude sweep: |V(f_in)| per cylinder (one amplitude per row)")
        self.failed_marks = _failed_marks(self)
        self.n_cells = 0
        self.n_failed = 0

    def show_sweep(self, scan: ScanView) -> None:
        a = scan.at_input  # [A, C]
        finite = np.isfinite(a) & (a > 0)
        self.n_cells = int(np.count_nonzero(finite))
        self.n_failed = int(np.count_nonzero(scan.failed))
        order = np.argsort(scan.cylinders)
        rows, cols = np.nonzero(scan.failed[:, order])
        self.failed_marks.setData(cols + 1.0, rows.astype(float))  # every amplitude's row
        if not finite.any():
            self.image.clear()
            return
        with np.errstate(divide="ignore", invalid="ignore"):
            row_max = np.max(np.where(finite, a, 0.0), axis=1, keepdims=True)
            img = np.log10(np.where(finite, a / np.where(row_max > 0, row_max, 1.0), np.nan))
        lo = max(float(np.nanmin(img)), -4.0)
        # a measured cell below the scale keeps its lowest colour; a missing one is NaN, drawn
        # transparent: both were the lowest colour before
        img = np.where(np.isfinite(img), np.maximum(img, lo), np.nan)
        img = img[:, order]
        self.image.setImage(img, levels=(lo, 0.0))
        self.colorbar.setLevels((lo, 0.0))
        n_a, n_c = img.shape
        self.image.setRect(pg.QtCore.QRectF(0.5, -0.5, n_c, n_a))
        cyl = scan.cylinders[order]
        self.getAxis("bottom").setTicks([[(k + 1, str(int(c))) for k, c in enumerate(cyl)]])
        factor, unit = amplitude_scale_text(scan.amplitudes, scan.amplitude_units)
        self.getAxis("left").setTicks(
            [[(k, f"{v / factor:.3g} {unit}") for k, v in enumerate(scan.amplitudes)]]
        )
        self.setLabel("left", "amplitude")
        failed = f"; {self.n_failed} failed: red x" if self.n_failed else ""
        self.setTitle(f"amplitude sweep ({scan.direction}): |V(f_in)|, normalised per row{failed}")


#: the maps' choice that shows the point being measured
FOLLOW = "maps: following the run"


class LiveViews(QTabWidget):
    """The tabs of live views, redrawn from a :class:`LiveData`."""

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        refcount_guard.install()
        self.trace = TraceView()
        self.spectrum = SpectrumView()
        self.spatial = SpatialMapView()
        self.bands = BandView()
        self.sweep = SweepView()
        self.addTab(self.trace, "Trace")
        self.addTab(self.spectrum, "Spectrum")
        self.addTab(self.spatial, "Spatial-frequency map")
        self.addTab(self.bands, "Quasi-bands")
        self.addTab(self.sweep, "Amplitude sweep")
        self.model_box = QCheckBox("model")
        self.model_box.setToolTip(
            "overlay the DEM's prediction for the point being measured: its spectrum (dashed) "
            "and every cylinder's predicted peak on the spatial-frequency map (crosses)"
        )
        self.model_box.setChecked(False)
        self.model_box.toggled.connect(self._model_toggled)
        # which direction and amplitude the two maps show: the point being measured, or one
        # chosen (before, only the last; a run of both directions hid the first after it)
        self.map_choice = QComboBox()
        self.map_choice.setToolTip("what the spatial-frequency and amplitude-sweep maps show")
        self.map_choice.addItem(FOLLOW, None)
        self.map_choice.currentIndexChanged.connect(self._choice_changed)
        corner = QWidget()
        row = QHBoxLayout(corner)
        row.setContentsMargins(0, 0, 4, 0)
        row.addWidget(self.map_choice)
        row.addWidget(self.model_box)
        self.setCornerWidget(corner)
        self.overlay: Any = None
        self._data: LiveData | None = None
        self._pending: set[tuple[Any, ...]] = set()
        self.on_model_error: Any = None
        self.n_redraws = 0

    def set_model(self, overlay: Any) -> None:
        """The :class:`analysis.model_overlay.ModelOverlay` of what is shown (or ``None``)."""
        self.overlay = overlay
        self._pending.clear()
        self._draw_model()

    def _model_toggled(self, on: bool) -> None:
        self._draw_model()

    def _draw_model(self) -> None:
        """Overlay the prediction for the last point, computing it on a worker thread once."""
        data, ov = self._data, self.overlay
        tr = data.last if data is not None else None
        if not self.model_box.isChecked() or ov is None or tr is None or data is None:
            self.spectrum.show_model(None, None)
            self.spatial.show_model_peaks(None)
            return
        scan = data.scans.get(tr.direction)
        f_range = (0.0, float(tr.freq_Hz[-1])) if tr.freq_Hz.size else (0.0, np.inf)
        pred = ov.cached(tr.direction, tr.amplitude, tr.amplitude_units, tr.time_s)
        if pred is None:
            key = (tr.direction, tr.amplitude, tr.amplitude_units, tr.time_s.size)
            if key in self._pending:
                return
            self._pending.add(key)
            from daq.gui.background import BackgroundCall

            def work() -> Any:
                return ov.predict(
                    tr.direction, tr.amplitude, tr.amplitude_units, tr.time_s, f_range
                )

            def done(_: Any, err: BaseException | None) -> None:
                self._pending.discard(key)
                if err is not None:
                    if self.on_model_error is not None:
                        self.on_model_error(f"model overlay: {err}")
                    return
                if ov is self.overlay:
                    self._draw_model()

            BackgroundCall(work, done, name="biafc-gui-model")
            return
        fmax = float(tr.freq_Hz[-1]) if tr.freq_Hz.size else np.inf
        sel = pred.freq_Hz <= fmax
        i = tr.cylinder - 1
        if 0 <= i < pred.magnitude.shape[0]:
            self.spectrum.show_model(pred.freq_Hz[sel], pred.magnitude[i, sel])
        if scan is not None:
            lo, hi = float(scan.freq_Hz[0]), float(scan.freq_Hz[-1])
            peaks = np.where((pred.peak_Hz >= lo) & (pred.peak_Hz <= hi), pred.peak_Hz, np.nan)
            self.spatial.show_model_peaks(peaks)

    def _choice_changed(self, _: int) -> None:
        if self._data is not None:
            self.redraw(self._data)

    def _update_choices(self, data: LiveData) -> None:
        """One entry per direction and amplitude of ``data``, after "following the run"."""
        wanted = [
            (f"{d} {amplitude_text(float(a), scan.amplitude_units)}", (d, ai))
            for d, scan in data.scans.items()
            for ai, a in enumerate(scan.amplitudes)
        ]
        have = [self.map_choice.itemData(i) for i in range(1, self.map_choice.count())]
        if have == [key for _, key in wanted]:
            return
        current = self.map_choice.currentData()
        self.map_choice.blockSignals(True)
        self.map_choice.clear()
        self.map_choice.addItem(FOLLOW, None)
        for text, key in wanted:
            self.map_choice.addItem(text, key)
        k = self.map_choice.findData(current) if current is not None else 0
        self.map_choice.setCurrentIndex(max(k, 0))
        self.map_choice.blockSignals(False)

    def redraw(self, data: LiveData) -> None:
        """Draw everything from ``data`` (called at most a few times a second)."""
        tr = data.last
        f_in = None
        if tr is None:  # nothing measured (an empty run file): before, the last file's stayed
            self.trace.c_vel.setData([], [])
            self.trace.c_drv.setData([], [])
            failed = f" ({data.n_failed} failed)" if data.n_failed else ""
            self.trace.p_vel.setTitle(f"no point measured{failed}")
            self.spectrum.curve.setData([], [])
            self.spatial.image.clear()
            self.spatial.failed_marks.setData([], [])
            self.spatial.setTitle(f"spatial-frequency map: no point measured{failed}")
            self.sweep.image.clear()
            self.sweep.failed_marks.setData([], [])
            for any_scan in data.scans.values():  # every point failed: the crosses still show
                if any_scan.failed.any():
                    self.sweep.show_sweep(any_scan)
                    break
        else:
            self.trace.show_trace(tr)
            if data.n_failed:  # the trace is the last measured point, not the last tried
                self.trace.p_vel.setTitle(
                    f"{self.trace.p_vel.titleLabel.text}  ·  {data.n_failed} point(s) failed"
                )
            scan = data.scans.get(tr.direction)
            f_in = scan.f_center_Hz if scan is not None else None
            self.spectrum.show_spectrum(tr, f_in or 0.0, data.chain)
            if f_in is not None:
                self.bands.set_input(f_in)
            self._update_choices(data)
            chosen = self.map_choice.currentData()
            if chosen is not None and chosen[0] in data.scans:  # one the person picked
                d, ai = chosen
                self.spatial.show_map(data.scans[d], int(ai), data.chain)
                self.sweep.show_sweep(data.scans[d])
            elif scan is not None:
                ai = int(np.argmin(np.abs(scan.amplitudes - tr.amplitude)))
                self.spatial.show_map(scan, ai, data.chain)
                self.sweep.show_sweep(scan)
        self._data = data
        self._draw_model()
        self.n_redraws += 1

    def show_chain(self, chain: ChainInfo | None, f_in_Hz: float | None = None) -> None:
        self.bands.show_chain(chain, f_in_Hz)
