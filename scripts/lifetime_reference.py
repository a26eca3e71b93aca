"""Holds `scatterscope lifetime`'s maps to independent computations.

    python3 lifetime_reference.py KIND FILE MAPS_DIR REFERENCE_LIFETIME_PS

KIND is `ptu` (decoded by ptufile), `sdt` (read by sdtfile) or `npy` (a
stack scatterscope binned, `stack.npy` with its JSON sidecar: the mock's
images). The command must have run with `--reference` a copy of FILE of
REFERENCE_LIFETIME_PS, `--harmonics 1,2`, into MAPS_DIR.

Per stack, over the pixels the maps do not mask:
- phasors (g, s) at harmonics 1 and 2: PhasorPy's `phasor_from_signal`
  with the bins' centres as sample phases, to 1e-6;
- calibrated phasors and apparent phase and modulation lifetimes:
  PhasorPy's `phasor_calibrate` (the reference: every pixel of every stack
  of FILE, centred by `phasor_center`'s intensity-weighted mean) and
  `phasor_to_apparent_lifetime`, to 1e-6 relative;
- mean arrival time after the onset and the centred fast lifetime:
  numpy, the onset found here as the half-maximum crossing of the summed
  decay's rising edge, to 1e-6 relative; the fast lifetime in
  SymPhoTime's conventions (photons at their bins' starts, time zero on
  the summed decay's rising flank, as `rising_flank_zero` here), to 1e-6
  relative; only the bins the instrument recorded whole (the reader's
  fields say which);
- the mask: fewer photons than the threshold, none at or after the
  onset, or a calibrated phasor without a finite apparent lifetime
  (PhasorPy's);
- the OME-TIFF (read by tifffile) holds the .npy's values, channel by
  channel, named as the sidecar names them (ome-types).

Prints one line per stack, `stack I: N pixels agree`; exits non-zero with
what differs.
"""

import json
import sys

import numpy as np
import tifffile
from ome_types import from_xml
from phasorpy.lifetime import phasor_calibrate, phasor_to_apparent_lifetime
from phasorpy.phasor import phasor_from_signal


def stacks_of(kind, path):
    """(stacks (rows, cols, bins) float64, bin starts ps, width ps, Hz,
    the bins recorded whole [first, end)), each from the reader: a PTU's
    bins ending within its sync period (MeasDesc_GlobalResolution), an
    .sdt's bins within its TAC limits (measure_info tac_ll, tac_lh,
    percent of the ADC's range)."""
    if kind == "ptu":
        import ptufile

        with ptufile.PtuFile(path) as f:
            d = f.decode_image(dtype="uint32")
            res = f.tags["MeasDesc_Resolution"] * 1e12
            freq = float(f.tags["TTResult_SyncRate"])
            period = f.tags["MeasDesc_GlobalResolution"] * 1e12
        stack = d.sum(axis=0)[:, :, 0, :].astype(np.float64)
        n = stack.shape[-1]
        end = min(n, int(np.floor(period / res + 1e-3)))
        return [stack], np.arange(n) * res, res, freq, (0, end)
    if kind == "sdt":
        import sdtfile

        f = sdtfile.SdtFile(path)
        starts = np.asarray(f.times[0], np.float64) * 1e12
        for t in f.times[1:]:
            assert np.allclose(np.asarray(t) * 1e12, starts), "blocks of other times"
        info = f.measure_info[0]
        freq = float(np.ravel(info["StopInfo"]["max_sync_rate"])[0])
        ll, lh = float(np.ravel(info["tac_ll"])[0]), float(np.ravel(info["tac_lh"])[0])
        n = len(starts)
        recorded = (0, n)
        if 0 <= ll < lh <= 100 and (ll > 0 or lh < 100):
            recorded = (int(np.ceil(ll / 100 * n - 1e-3)), int(np.floor(lh / 100 * n + 1e-3)))
        return [a.astype(np.float64) for a in f.data], starts, starts[1] - starts[0], freq, recorded
    if kind == "npy":
        meta = json.load(open(path[: -len(".npy")] + ".json"))
        stack = np.moveaxis(np.load(path).astype(np.float64), 0, -1)
        starts = np.asarray(meta["bin_starts_ps"], np.float64)
        r = meta.get("recorded_bins")
        recorded = (r["first"], r["end"]) if r else (0, len(starts))
        return [stack], starts, float(meta["bin_width_ps"]), float(meta["laser_frequency_hz"]), recorded
    raise SystemExit(f"unknown kind {kind}")


def rising_flank_zero(summed, starts, width):
    """SymPhoTime's time zero: the line through the steepest-rising pair
    of bins before the peak (at their starts), extended to the peak's
    count, less half a bin."""
    peak = int(np.argmax(summed))
    rises = np.diff(summed[: peak + 1])
    k = int(np.argmax(rises))
    return starts[k] + (summed[peak] - summed[k]) / rises[k] * width - width / 2.0


def onset_of(summed, centres):
    peak = int(np.argmax(summed))
    half = summed[peak] / 2.0
    below = np.nonzero(summed[: peak + 1] < half)[0]
    if len(below) == 0:
        return centres[0]
    k = below[-1]
    a, b = summed[k], summed[k + 1]
    return centres[k] + (half - a) / (b - a) * (centres[k + 1] - centres[k])


def check(name, ours, theirs, rtol, atol, failures):
    both = np.isfinite(ours) & np.isfinite(theirs)
    if (np.isfinite(ours) != np.isfinite(theirs)).any():
        n = int((np.isfinite(ours) != np.isfinite(theirs)).sum())
        failures.append(f"{name}: {n} pixels finite in one and not the other")
    bad = ~np.isclose(ours[both], theirs[both], rtol=rtol, atol=atol)
    if bad.any():
        i = np.argmax(np.abs(ours[both] - theirs[both]))
        failures.append(
            f"{name}: {int(bad.sum())} of {int(both.sum())} differ, worst {ours[both][i]} vs {theirs[both][i]}"
        )


def main():
    kind, path, out, tau_ref_ps = sys.argv[1], sys.argv[2], sys.argv[3], float(sys.argv[4])
    stacks, starts, width, freq, (first_bin, end_bin) = stacks_of(kind, path)
    # The reader's time axis and ours agree to float32's digits; the
    # phasors are compared on the same stacks, so on ours (scatterscope
    # keeps the 7 digits a float32 TAC range carries, sdtfile its binary
    # value: 1e-8 apart, which moves a phase lifetime of 1e7 ps, from a
    # pixel whose g is 1e-4, by more than 1e-6).
    tail0 = "_f000" if len(stacks) > 1 else ""
    stated = json.load(open(f"{out}/maps{tail0}.json"))["stack"]
    ours = np.asarray(stated["bin_starts_ps"], np.float64)
    if len(ours) != len(starts) or not np.allclose(ours, starts, rtol=1e-7, atol=1e-6):
        raise SystemExit(f"time axes differ: {ours[:3]}... vs {starts[:3]}...")
    if not np.isclose(stated["laser_frequency_hz"], freq, rtol=1e-9):
        raise SystemExit(f"laser frequency {stated['laser_frequency_hz']} vs {freq}")
    starts, width = ours, float(stated["bin_width_ps"])
    # The maps keep the bins the instrument recorded whole, found here
    # from the reader's fields.
    theirs = stated.get("recorded_bins")
    stated_bins = (theirs["first"], theirs["end"]) if theirs else (0, len(starts))
    if stated_bins != (first_bin, end_bin):
        raise SystemExit(f"recorded bins: ours {theirs}, the reader's fields {first_bin}:{end_bin}")
    stacks = [s[..., first_bin:end_bin] for s in stacks]
    starts = starts[first_bin:end_bin]
    centres = starts + width / 2.0
    harmonics = (1, 2)
    phases = {h: 2 * np.pi * h * freq * centres * 1e-12 for h in harmonics}
    # The reference: every pixel of every stack of the file.
    reference = np.concatenate(stacks, axis=0)
    ref = {h: phasor_from_signal(reference, axis=-1, sample_phase=phases[h]) for h in harmonics}
    failures = []
    for i, stack in enumerate(stacks):
        tail = f"_f{i:03d}" if len(stacks) > 1 else ""
        maps = np.load(f"{out}/maps{tail}.npy").astype(np.float64)
        side = json.load(open(f"{out}/maps{tail}.json"))
        names = side["channels"]
        ch = {n: maps[j] for j, n in enumerate(names)}
        masked = ch["mask (1: fewer photons than the threshold)"] == 1
        keep = ~masked
        photons = stack.sum(axis=-1)
        if not np.array_equal(ch["photons"], photons):
            failures.append(f"stack {i}: photons differ")
        summed = stack.sum(axis=(0, 1))
        onset = onset_of(summed, centres)
        first = int(np.searchsorted(centres, onset, side="left"))
        n_after = stack[..., first:].sum(axis=-1)
        finite = np.ones(photons.shape, bool)
        for h in harmonics:
            _, g, s = phasor_from_signal(stack, axis=-1, sample_phase=phases[h])
            rm, rg, rs = ref[h]
            gc, sc = phasor_calibrate(
                g, s, rm, rg, rs, frequency=freq * 1e-6, lifetime=tau_ref_ps * 1e-3, harmonic=h
            )
            with np.errstate(invalid="ignore", divide="ignore"):
                tp, tm = phasor_to_apparent_lifetime(gc, sc, frequency=freq * h * 1e-6)
            finite &= np.isfinite(tp) & np.isfinite(tm)
        want = (photons < side["min_photons"]) | (n_after == 0) | ~finite
        if not np.array_equal(masked, want):
            failures.append(
                f"stack {i}: the mask ({masked.sum()} pixels) is not photons < {side['min_photons']}, "
                f"none after the onset or no finite apparent lifetime ({want.sum()} pixels)")
        for h in harmonics:
            _, g, s = phasor_from_signal(stack, axis=-1, sample_phase=phases[h])
            check(f"stack {i} g{h}", ch[f"g harmonic {h}"][keep], g[keep], 0, 1e-6, failures)
            check(f"stack {i} s{h}", ch[f"s harmonic {h}"][keep], s[keep], 0, 1e-6, failures)
            rm, rg, rs = ref[h]
            gc, sc = phasor_calibrate(
                g, s, rm, rg, rs, frequency=freq * 1e-6, lifetime=tau_ref_ps * 1e-3, harmonic=h
            )
            check(f"stack {i} g{h} calibrated", ch[f"g calibrated harmonic {h}"][keep], gc[keep], 0, 1e-6, failures)
            check(f"stack {i} s{h} calibrated", ch[f"s calibrated harmonic {h}"][keep], sc[keep], 0, 1e-6, failures)
            tp, tm = phasor_to_apparent_lifetime(gc, sc, frequency=freq * h * 1e-6)
            check(f"stack {i} phase lifetime {h}", ch[f"phase lifetime harmonic {h} (ps)"][keep], tp[keep] * 1e3, 1e-6, 1e-3, failures)
            check(f"stack {i} modulation lifetime {h}", ch[f"modulation lifetime harmonic {h} (ps)"][keep], tm[keep] * 1e3, 1e-6, 1e-3, failures)
        if not np.isclose(side["onset_ps"], onset, rtol=1e-9, atol=0):
            failures.append(f"stack {i}: onset {side['onset_ps']} vs {onset}")
        first = int(np.searchsorted(centres, onset, side="left"))
        after = stack[..., first:]
        n_after = after.sum(axis=-1)
        with np.errstate(invalid="ignore", divide="ignore"):
            mean = (after * (centres[first:] - onset)).sum(axis=-1) / n_after
            barycentre = (stack * centres).sum(axis=-1) / photons
        centred = barycentre - onset
        zero_start = rising_flank_zero(summed, starts, width)
        fast = barycentre - width / 2.0 - zero_start
        check(f"stack {i} mean arrival time", ch["mean arrival time after onset (ps)"][keep], mean[keep], 1e-6, 1e-3, failures)
        check(f"stack {i} fast lifetime", ch["fast lifetime (ps)"][keep], fast[keep], 1e-6, 1e-3, failures)
        check(f"stack {i} centred fast lifetime", ch["fast lifetime centred (ps)"][keep], centred[keep], 1e-6, 1e-3, failures)
        for name, m in ch.items():
            if name.startswith("mask") or name == "photons":
                continue
            if np.isfinite(m[masked]).any():
                failures.append(f"stack {i}: {name} is not NaN where masked")
        with tifffile.TiffFile(f"{out}/maps{tail}.ome.tif") as t:
            pages = t.asarray()
            xml = from_xml(t.ome_metadata)
        tif_names = [c.name for c in xml.images[0].pixels.channels]
        if tif_names != names:
            failures.append(f"stack {i}: OME channels {tif_names} vs sidecar {names}")
        if pages.dtype != np.float32 or not np.array_equal(pages, maps.astype(np.float32), equal_nan=True):
            failures.append(f"stack {i}: the OME-TIFF's values are not the .npy's ({pages.dtype}, {pages.shape})")
        print(f"stack {i}: {int(keep.sum())} pixels agree")
    if failures:
        raise SystemExit("\n".join(failures))


if __name__ == "__main__":
    main()
