"""``python -m dtradar_data channels NAME``: a stored dataset's channels for chosen arrays and subcarriers, written as
one ``.npz`` (numpy) file: the CLI face of :class:`~dtradar_data.channels.ChannelGenerator`."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Annotated

import numpy as np
import tyro

from dtradar_data.channels.arrays import Array
from dtradar_data.channels.generator import ChannelGenerator, ofdm_frequencies
from dtradar_data.core.files import write_atomic
from dtradar_data.store import local


@dataclass(frozen=True)
class ChannelsCmd:
    """Generate a dataset's channels (frequency response per free cell; --cir adds taps and delays) for chosen
    transmit and receive arrays (Sionna's PlanarArray: rows, cols, pattern, polarization, spacings in wavelengths) on
    an OFDM grid around the traced carrier, into an .npz file. Needs a version built with --rt.path-channels. Array
    options left out take the dataset's own arrays (the paper's)."""

    name: tyro.conf.Positional[str]
    """Dataset name, e.g. cubicle/blueprint or cubicle/blueprint@v1."""
    out: Annotated[Path, tyro.conf.arg(metavar="FILE.npz")] = Path("channels.npz")
    """Where to write: ix, iy, frequencies_hz, h [cells, rx ports, tx ports, subcarriers] (complex64)."""
    subcarriers: int = 64
    """Number of subcarriers (Sionna's subcarrier_frequencies grid)."""
    spacing_hz: float = 30e3
    """Subcarrier spacing, Hz."""
    tx_rows: int | None = None
    tx_cols: int | None = None
    tx_pattern: str | None = None
    tx_polarization: str | None = None
    tx_spacing: float = 0.5
    """Transmit array: rows, columns, pattern (iso, dipole, hw_dipole, tr38901), polarization (V, H, VH, cross),
    element spacing (wavelengths, both directions)."""
    rx_rows: int | None = None
    rx_cols: int | None = None
    rx_pattern: str | None = None
    rx_polarization: str | None = None
    rx_spacing: float = 0.5
    """Receive array, as the transmit one."""
    cir: bool = False
    """Also write the impulse response: a [cells, rx ports, tx ports, paths], tau_s [cells, paths], num_paths."""
    batch_cells: int = 512
    """Cells generated at a time (memory)."""

    def run(self) -> int:
        ds = local.load(self.name, paths=True)
        tx_meta, rt = ds.meta["transmitter"], ds.meta["rt"]
        tx = Array(
            self.tx_rows or tx_meta["num_rows"],
            self.tx_cols or tx_meta["num_cols"],
            self.tx_pattern or tx_meta["pattern"],
            self.tx_polarization or tx_meta["polarization"],
            self.tx_spacing,
            self.tx_spacing,
        )
        rx = Array(
            self.rx_rows or 1,
            self.rx_cols or 1,
            self.rx_pattern or rt["rx_pattern"],
            self.rx_polarization or rt["rx_polarization"],
            self.rx_spacing,
            self.rx_spacing,
        )
        gen = ChannelGenerator(ds, tx, rx, frequencies_hz=ofdm_frequencies(self.subcarriers, self.spacing_hz))
        parts = list(gen.batches(batch_cells=self.batch_cells))
        arrays = {
            "ix": np.concatenate([p.ix for p in parts]),
            "iy": np.concatenate([p.iy for p in parts]),
            "frequencies_hz": gen.frequencies_hz,
            "carrier_hz": np.float64(gen.carrier_hz),
            "h": np.concatenate([p.h for p in parts]),
        }
        if self.cir:  # batches differ in their most paths: padded to the widest (zero taps, delay -1)
            width = max(p.a.shape[-1] for p in parts)
            arrays["a"] = np.concatenate([np.pad(p.a, [(0, 0)] * 3 + [(0, width - p.a.shape[-1])]) for p in parts])
            arrays["tau_s"] = np.concatenate(
                [np.pad(p.tau_s, [(0, 0), (0, width - p.tau_s.shape[-1])], constant_values=-1.0) for p in parts]
            )
            arrays["num_paths"] = np.concatenate([p.num_paths for p in parts])
        import io

        buf = io.BytesIO()
        np.savez(buf, **arrays)
        write_atomic(self.out, buf.getvalue())
        cells, nr, nt, nf = arrays["h"].shape
        print(
            f"{ds.name}@{ds.version}: {cells} cells, {nr} rx x {nt} tx ports ({rx.pattern} {rx.polarization} <- "
            f"{tx.num_rows}x{tx.num_cols} {tx.pattern} {tx.polarization}), {nf} subcarriers -> {self.out}"
        )
        return 0
