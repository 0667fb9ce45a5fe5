"""How finely a volume's u*/v* lattice must sample F: F's own spectrum over (u, v) against the lattice's Nyquist.

    python -m analysis.lattice_band_limit HEIGHTFIELD [--centre 0.5,0] [--w -1.5] [--span 0.25]
        [--points 512] [--wavelengths 380,550,780] [--resolutions 1001,2001] [--plot PNG]

HEIGHTFIELD and its optics and load flags (--sigma-s, --dx-um, …) are those of ``gratnet groundtruth``.

Physics (docs/physics.md, "How finely to sample u and v"): at one λ and w, F = |P|² with P the Fourier transform
of the windowed field g·e^{ikwh} (eq. 1). F's own spectrum over (u, v) is therefore that field's autocorrelation:
a component of frequency f (cycles per unit of u) comes from pairs of surface points Δx = f·λ apart. It is exactly
zero beyond the integration width (|Δx| > 6σs per axis), and its magnitude is bounded by the window's own
autocorrelation, so its power falls at least like exp(−Δx²/(2σs²)) (Cauchy–Schwarz). A lattice of local spacing
δu holds frequencies up to 1/(2δu), offsets up to Δx_N = λ/(2δu). The simple schemes' spacing is
δu ≈ |u*|·4/(R − 1); the regular scheme's 4/(R − 1).

Computes monochromatic F (constant w) on a fine points² patch, span × span around the centre, and its power
spectrum (mean removed, Hann-windowed). Per λ and per resolution R, with the R² lattice's own spacing at the
centre (scheme of --scheme), it prints the share of F's fluctuation power

- ``beyond_nyquist``: at frequencies the lattice cannot hold (aliased into the samples);
- ``beyond_half_nyquist``: above half of it, where linear interpolation between samples loses more than 29 % of a
  component's amplitude at the cell centres (1 − cos(π/4)).

``beyond_extent`` (offsets past the integration width) is a check: it is float32 rounding, about 1e-9, wherever
F is well above rounding (``mean_f``: F relative to a flat mirror's peak). Where F is itself at the rounding floor
(e.g. a 1-D grating away from v = 0, mean_f ≈ 1e-12), every share is noise: pick a centre on the signal.

One JSON line per λ; ``--plot`` draws the radially averaged spectra with the envelope and the Nyquist lines.
"""

from __future__ import annotations

import argparse
import json

import numpy as np

from gratnet.atomic import check_output_file
from gratnet.figures import save_figure
from gratnet.volume import volume_axes
from trainer.cli_support import add_heightfield_input, read_heightfield_input
from trainer.fourier import FTerm, PreparedSurface, prepare_surface
from trainer.sampling import Scheme, check_scheme, grid_to_key
from trainer.spectral import monochromatic


def lattice_spacing(resolution: int, scheme: Scheme, key: float) -> float:
    """The gap between the two R-lattice nodes around key-vector component ``key`` (u or v), in units of u."""
    nodes = grid_to_key(volume_axes(resolution), check_scheme(scheme))
    index = int(np.clip(np.searchsorted(nodes, key), 1, len(nodes) - 1))
    return float(nodes[index] - nodes[index - 1])


def f_patch(surface: PreparedSurface, wavelength_nm: float, centre: tuple[float, float], w: float, span: float,
            points: int) -> tuple[np.ndarray, float]:
    """Monochromatic F on a points² patch of side ``span`` (units of u) centred on ``centre``, and its spacing."""
    offsets = (np.arange(points) - points / 2) * (span / points)
    f_term = FTerm(surface, monochromatic(wavelength_nm))
    return f_term.xyz_grid(centre[0] + offsets, centre[1] + offsets, [w])[0, :, :, 1], span / points


def power_spectrum(values: np.ndarray, spacing: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Power of (values − mean)·Hann over frequency: (power (rows v, columns u), f_u, f_v) in cycles per unit u,
    DC removed."""
    hann = np.hanning(values.shape[0])
    window = np.outer(hann, hann)
    spectrum = np.fft.fftshift(np.abs(np.fft.fft2((values - values.mean()) * window)) ** 2)
    frequencies = np.fft.fftshift(np.fft.fftfreq(values.shape[0], d=spacing))
    return spectrum, frequencies, frequencies.copy()


def share_beyond(power: np.ndarray, f_u: np.ndarray, f_v: np.ndarray, limit_u: float, limit_v: float) -> float:
    """Share of the power at |f_u| > limit_u or |f_v| > limit_v (a lattice's rectangle of representable
    frequencies)."""
    outside = (np.abs(f_u)[None, :] > limit_u) | (np.abs(f_v)[:, None] > limit_v)
    return float(power[outside].sum() / power.sum())


def radial_profile(power: np.ndarray, f_u: np.ndarray, f_v: np.ndarray, bins: int) -> tuple[np.ndarray, np.ndarray]:
    """Mean power in rings of |f| (centres, means), up to the patch's own Nyquist along an axis."""
    radius = np.hypot(f_u[None, :], f_v[:, None])
    edges = np.linspace(0.0, float(np.abs(f_u).max()), bins + 1)
    ring = np.digitize(radius.ravel(), edges) - 1
    kept = (ring >= 0) & (ring < bins)
    sums = np.bincount(ring[kept], weights=power.ravel()[kept], minlength=bins)
    counts = np.bincount(ring[kept], minlength=bins)
    return 0.5 * (edges[1:] + edges[:-1]), sums / np.maximum(counts, 1)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_heightfield_input(parser)  # the ground-truth subcommands' HEIGHTFIELD with its optics and load flags
    parser.add_argument("--centre", default="0.5,0", help="key vector (u, v) at the patch centre")
    parser.add_argument("--w", type=float, default=-1.5, help="w of the patch (constant)")
    parser.add_argument("--span", type=float, default=0.25, help="patch side in units of u")
    parser.add_argument("--points", type=int, default=512, help="samples per patch side")
    parser.add_argument("--wavelengths", default="380,550,780", help="λ in nm, comma-separated")
    parser.add_argument("--resolutions", default="1001,2001", help="lattice resolutions R to compare")
    parser.add_argument("--scheme", default="simple-max", help="the lattices' sampling scheme")
    parser.add_argument("--plot", help="PNG of the radially averaged spectra")
    arguments = parser.parse_args()
    centre = tuple(float(part) for part in arguments.centre.split(","))
    if len(centre) != 2 or np.hypot(*centre) + arguments.span / np.sqrt(2) > 2.0:
        parser.error("--centre must be 'u,v' with the whole patch inside u² + v² ≤ 4")
    if not -2.0 <= arguments.w <= 0.0 or arguments.points < 16:
        parser.error("--w must lie in [−2, 0] and --points be at least 16")
    resolutions = [int(part) for part in arguments.resolutions.split(",")]
    wavelengths = [float(part) for part in arguments.wavelengths.split(",")]
    check_scheme(arguments.scheme)
    if arguments.plot:
        check_output_file(arguments.plot, "--plot")
    field, optics, _ = read_heightfield_input(arguments)
    sigma_s_um = optics.sigma_s_um
    surface = prepare_surface(field, optics)

    profiles = []
    for wavelength_nm in wavelengths:
        values, spacing = f_patch(surface, wavelength_nm, centre, arguments.w, arguments.span, arguments.points)
        power, f_u, f_v = power_spectrum(values, spacing)
        row: dict[str, object] = {"heightfield": arguments.heightfield, "wavelength_nm": wavelength_nm,
                                  "centre": centre, "w": arguments.w, "sigma_s_um": sigma_s_um,
                                  "extent_um": optics.extent_um, "mean_f": float(values.mean()),
                                  "beyond_extent": share_beyond(power, f_u, f_v, *(2 * [optics.extent_um
                                                                                        / (wavelength_nm / 1e3)]))}
        for resolution in resolutions:
            nyquist_u = 0.5 / lattice_spacing(resolution, arguments.scheme, centre[0])
            nyquist_v = 0.5 / lattice_spacing(resolution, arguments.scheme, centre[1])
            row[str(resolution)] = {
                "nyquist_offset_um": [round(nyquist_u * wavelength_nm / 1e3, 2),
                                      round(nyquist_v * wavelength_nm / 1e3, 2)],
                "beyond_nyquist": share_beyond(power, f_u, f_v, nyquist_u, nyquist_v),
                "beyond_half_nyquist": share_beyond(power, f_u, f_v, nyquist_u / 2, nyquist_v / 2),
            }
        print(json.dumps(row), flush=True)
        profiles.append((wavelength_nm, *radial_profile(power, f_u, f_v, arguments.points // 4)))

    if arguments.plot:
        plot(arguments.plot, profiles, resolutions, arguments.scheme, centre, sigma_s_um, optics.extent_um,
             arguments.heightfield)


def plot(path: str, profiles: list[tuple[float, np.ndarray, np.ndarray]], resolutions: list[int], scheme: Scheme,
         centre: tuple[float, ...], sigma_s_um: float, extent_um: float, name: str) -> None:
    """Radially averaged spectra against frequency, with exp(−(fλ)²/(2σs²)) and each lattice's Nyquist along u."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure, axes = plt.subplots(figsize=(7.5, 4.2), dpi=130)
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for (wavelength_nm, frequency, mean), colour in zip(profiles, colours, strict=False):
        scale = mean[1:4].mean()
        axes.semilogy(frequency, mean / scale, color=colour, label=f"F at λ = {wavelength_nm:g} nm")
        offset = frequency * wavelength_nm / 1e3
        axes.semilogy(frequency, np.exp(-offset**2 / (2 * sigma_s_um**2)), color=colour, linestyle=":",
                      label=f"bound ∝ exp(−(fλ)²/2σs²), {wavelength_nm:g} nm")
        axes.axvline(extent_um / (wavelength_nm / 1e3), color=colour, linewidth=0.6, alpha=0.5)
    for resolution, style in zip(resolutions, ("--", "-.", (0, (1, 1)), "-"), strict=False):
        axes.axvline(0.5 / lattice_spacing(resolution, scheme, centre[0]), color="black", linestyle=style,
                     label=f"Nyquist along u of the {resolution}² lattice")
    axes.set_ylim(1e-8, 10)
    widest = extent_um / (min(profile[0] for profile in profiles) / 1e3)  # the band limit of the shortest λ
    axes.set_xlim(0, min(1.15 * widest, float(profiles[0][1].max())))
    axes.set_xlabel("frequency of F over u (cycles per unit of u) = surface offset Δx / λ")
    axes.set_ylabel("radially averaged power (relative)")
    axes.set_title(f"{name}: F's spectrum near (u, v) = ({centre[0]:g}, {centre[1]:g}); thin lines: 6σs / λ",
                   fontsize=9)
    axes.legend(fontsize=6.5, ncol=2)
    figure.tight_layout()
    save_figure(figure, path)


if __name__ == "__main__":
    main()
