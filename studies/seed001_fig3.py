"""Seed 001 Fig. 3: the elevation of an added transmitter that minimises the HPL.

One realization (seed 001 section 3.3): M GPS satellites with az ~ U(0, 2 pi) and
el ~ U(mask, pi/2), one more transmitter at az ~ U(0, 2 pi); its elevation is swept over
[0, pi/2] on a grid of ``el_step_deg`` (DESIGN.md: 0.5 deg, ties to the lowest elevation) and the
elevation el* of the smallest HPL is recorded. With dof = M + 1 - 4 fixed, HPL = slope_max
sqrt(lambda_det) is minimised where slope_max is, so P_FA and P_MD do not enter; with equal
sigmas the common sigma cancels too (the seed gives none).
"""

import functools

import jax
import jax.numpy as jnp
import numpy as np
import xarray as xr

from oaraim import geometry
from oaraim.araim import added_source_slope_max
from oaraim.mc import Histogram, run_chunked
from oaraim.studies.base import Param, Study, StudyResult, count, in_range, positive
from oaraim.studies.common import params as shared


def draw(key, n_gps, mask_rad):
    """One realization's random draws: GPS (az, el) and the added transmitter's azimuth."""
    k_sky, k_az = jax.random.split(key)
    az, el = geometry.random_sky(k_sky, n_gps, mask_rad)
    return az, el, jax.random.uniform(k_az, (), jnp.float64, 0.0, 2.0 * jnp.pi)


@functools.partial(jax.jit, static_argnames=("n_gps",))
def fig3_kernel(keys, n_gps, mask_rad, el_grid_rad, sigma_gps_m, sigma_added_m):
    """Per realization: index into the elevation grid of the HPL-minimising elevation (-1 if the
    base geometry is singular) and the minimum slope_max."""
    az, el, az_added = jax.vmap(lambda k: draw(k, n_gps, mask_rad))(keys)
    g = geometry.geometry_rows(az, el)
    sigma = jnp.full(az.shape, sigma_gps_m)
    slope_max, ok = added_source_slope_max(g, sigma, az_added, el_grid_rad, sigma_added_m,
                                           jnp.ones(az.shape, bool))
    idx = jnp.argmin(slope_max, axis=-1)  # first occurrence: ties go to the lowest elevation
    best = jnp.take_along_axis(slope_max, idx[:, None], axis=-1)[:, 0]
    ok = ok & jnp.isfinite(best)
    return {"el_star_index": jnp.where(ok, idx, -1).astype(jnp.int32),
            "slope_max_min": jnp.where(ok, best, jnp.inf)}


class Fig3Elevation(Study):
    """Seed 001 Fig. 3 (module docstring): the histogram of the HPL-minimising elevation el*
    of an added transmitter."""

    name = "seed001-fig3-elevation"
    title = "Seed 001 Fig. 3: elevation of an added transmitter that minimises the HPL"
    seed_file = "001_c7da69deb44e932b.txt"
    realization = "one random 5-satellite sky and one added transmitter azimuth"
    default_realizations = 1_000_000
    quick_realizations = 200_000
    quick_cost_s = 6
    params = {
        "n_gps": Param(5, count(4, 30), "GPS satellites M (seed 001 Fig. 3: 5)"),
        "mask_deg": shared.MASK_SEED001_DEG,
        "el_step_deg": Param(0.5, in_range(0.01, 15.0),
                             "elevation sweep resolution (DESIGN.md: 0.5 deg)", "deg"),
        "sigma_gps_m": Param(1.0, positive, "GPS pseudorange sigma (cancels if equal)", "m"),
        "sigma_added_m": Param(1.0, positive, "added transmitter's pseudorange sigma", "m"),
        "chunk": Param(16384, count(1024), "realizations per kernel call (memory bound)"),
    }

    def el_grid_deg(self, params):
        """The elevation sweep 0, el_step_deg, ... up to 90 deg (deg)."""
        n = int(np.floor(90.0 / params["el_step_deg"] + 1e-9))
        return np.arange(n + 1) * params["el_step_deg"]

    def run(self, params, realizations, seed, progress):
        """Histogram of el* over the realizations, its mode and the share at 0 deg."""
        grid_deg = self.el_grid_deg(params)
        step = params["el_step_deg"]
        hist = Histogram("el_star_deg",
                         np.concatenate([grid_deg - step / 2, [grid_deg[-1] + step / 2]]))
        kernel = functools.partial(
            fig3_kernel, n_gps=params["n_gps"], mask_rad=np.deg2rad(params["mask_deg"]),
            el_grid_rad=jnp.asarray(np.deg2rad(grid_deg)), sigma_gps_m=params["sigma_gps_m"],
            sigma_added_m=params["sigma_added_m"])

        def on_chunk(start, out):
            idx = out["el_star_index"]
            el = np.where(idx >= 0, grid_deg[np.maximum(idx, 0)], np.inf)
            hist.update(start, el)

        run_chunked(kernel, realizations, seed=seed, chunk_size=params["chunk"],
                    on_chunk=on_chunk, progress=progress)
        share = hist.counts / max(hist.total, 1)
        mode_deg = float(grid_deg[np.argmax(hist.counts)])
        share0 = float(share[0])
        below_mask = float(share[grid_deg < params["mask_deg"]].sum())
        ds = xr.Dataset(
            {"count": ("el_star_deg", hist.counts), "share": ("el_star_deg", share)},
            coords={"el_star_deg": grid_deg},
            attrs={"realizations": int(hist.total), "singular": int(hist.outside)},
        )
        rows = [
            {"quantity": "most frequent HPL-minimising elevation el*", "unit": "deg",
             "published": 0.0, "reproduced": mode_deg,
             "note": "Fig. 3 peaks at 0 deg: 'terrestrial transmitters (at zero elevation angle) "
                     "are more likely to minimize the HPL'"},
            {"quantity": "share of realizations with el* = 0 deg", "unit": "%",
             "published": None, "reproduced": 100.0 * share0,
             "note": "read from the histogram; the paper prints no number"},
        ]
        metrics = {"share_el_star_0deg_pct": 100.0 * share0,
                   "share_el_star_below_mask_pct": 100.0 * below_mask,
                   "share_el_star_90deg_pct": 100.0 * float(share[-1]),
                   "singular_base_geometries": int(hist.outside),
                   "el_grid_points": int(grid_deg.size)}
        return StudyResult(ds, rows, metrics)

    def plot(self, out_dir):
        """fig3_elevation_histogram.png: share of realizations per el* bin, 0 deg in red."""
        import matplotlib.pyplot as plt

        ds = xr.open_zarr(f"{out_dir}/data.zarr", consolidated=False).load()
        el = ds["el_star_deg"].values
        share = 100.0 * ds["share"].values
        step = float(el[1] - el[0])
        fig, ax = plt.subplots(figsize=(6.4, 3.8))
        ax.bar(el, share, width=step, align="center", color="tab:blue", edgecolor="none")
        ax.bar(el[:1], share[:1], width=step, color="tab:red",
               label=f"el* = 0 deg: {share[0]:.1f} %")
        ax.set_xlabel("elevation angle el* of the added transmitter that minimises the HPL (deg)")
        ax.set_ylabel(f"share of realizations per {step:g} deg bin (%)")
        ax.set_xlim(-1, 91)
        n = int(ds.attrs["realizations"])
        ax.set_title(f"Seed 001 Fig. 3: M = 5 GPS, 15 deg mask, {n:,} realizations", fontsize=10)
        ax.legend()
        fig.tight_layout()
        path = f"{out_dir}/fig3_elevation_histogram.png"
        fig.savefig(path, dpi=120)
        plt.close(fig)
        return [path]
