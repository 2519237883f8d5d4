"""Fault corpus of ``microsim.testing`` and the closed forms users call with their own arrays:
a damaged or unreadable reference cache entry is reported in one warning line naming the
file, discarded and traced again (also while another process holds its lock); what a user's
BRDF, sampler or pdf returns must be real numbers of the stated shape; mismatched array shapes
and bad harness arguments are refused with a one-line ``UsageError`` naming them.

References are tiny (200 Beckmann V-grooves, 2·10⁴ rays, one incidence, 9 × 10 bins)."""

import json
import shutil
import threading
import time
import warnings

import numpy as np
import pytest
from support import refused

from microsim import atomic
from microsim.analytic import (
    GGX,
    AlbedoTable,
    Beckmann,
    mikkelsen_mix,
    pdf_microfacet,
    sample_microfacet,
    torrance_sparrow,
)
from microsim.surfaces import vgrooves
from microsim.testing import assert_brdf_agrees, assert_sampler_matches, pearson_chi2, reference
from microsim.testing import cache as cache_mod

AL = "aluminium"
TINY = dict(rays=20_000, bins=(9, 10))


@pytest.fixture(scope="module")
def surface():
    return vgrooves(200, Beckmann(0.3))


@pytest.fixture(scope="module")
def good(surface, tmp_path_factory):
    """A cache holding one good entry: (cache root, entry name, the reference's BRDF)."""
    root = tmp_path_factory.mktemp("cache")
    res = reference(surface, AL, [30], cache=root, **TINY)
    (name,) = [p.name for p in root.iterdir() if not p.name.startswith(".")]
    return root, name, res.brdf


@pytest.fixture
def traces(monkeypatch):
    """The number of references traced during the test (a list, appended to per trace)."""
    done = []
    original = cache_mod._trace

    def counted(ref, threads):
        done.append(ref.key())
        return original(ref, threads)

    monkeypatch.setattr(cache_mod, "_trace", counted)
    return done


# --- damaged cache entries ------------------------------------------------------------------
def truncate(path):
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])


def edit_meta(change):
    def damage(path):
        meta = json.loads(path.read_text())
        change(meta)
        path.write_text(json.dumps(meta))

    return damage


def edit_arrays(change):
    def damage(path):
        with np.load(path) as z:
            arrays = {k: z[k] for k in z.files}
        change(arrays)
        with open(path, "wb") as fh:
            np.savez(fh, **arrays)

    return damage


def replace_by_folder(path):
    path.unlink()
    path.mkdir()


DAMAGES = {
    "truncated npz": ("brdf.npz", truncate),
    "npz unreadable": ("brdf.npz", replace_by_folder),
    "npz brdf cut": ("brdf.npz", edit_arrays(lambda a: a.update(brdf=a["brdf"][:, 1:]))),
    "npz negative stderr": ("brdf.npz", edit_arrays(lambda a: a.update(stderr=-a["stderr"] - 1))),
    "npz without counts": ("brdf.npz", edit_arrays(lambda a: a.pop("counts"))),
    "meta bins a list": ("meta.json", edit_meta(lambda m: m.update(bins=[9, 10]))),
    "meta bins 8 x 10": ("meta.json", edit_meta(lambda m: m["bins"].update(n_theta=8))),
    "meta not JSON": ("meta.json", lambda p: p.write_text('{"bins": ')),
    "meta missing": ("meta.json", lambda p: p.unlink()),
    "key.json empty": ("key.json", lambda p: p.write_text("")),
}


@pytest.mark.parametrize("case", list(DAMAGES))
def test_a_damaged_entry_is_reported_once_discarded_and_traced_again(
    case, surface, good, tmp_path, traces
):
    root, name, brdf = good
    shutil.copytree(root / name, tmp_path / name)
    file, damage = DAMAGES[case]
    damage(tmp_path / name / file)
    with pytest.warns(UserWarning) as caught:
        res = reference(surface, AL, [30], cache=tmp_path, **TINY)
    (warning,) = caught
    msg = str(warning.message)
    assert str(tmp_path / name / file) in msg and "\n" not in msg, msg
    assert traces == [name]
    np.testing.assert_array_equal(res.brdf, brdf)
    with warnings.catch_warnings():  # the entry traced again is used from now on
        warnings.simplefilter("error")
        again = reference(surface, AL, [30], cache=tmp_path, **TINY)
    assert traces == [name]
    np.testing.assert_array_equal(again.brdf, brdf)
    left = sorted(p.name for p in tmp_path.iterdir())
    assert left == [name], left  # no lock, staging or discarded copy left behind


def test_a_check_on_a_damaged_entry_traces_it_again(surface, good, tmp_path, traces):
    root, name, _ = good
    shutil.copytree(root / name, tmp_path / name)
    truncate(tmp_path / name / "brdf.npz")
    with pytest.warns(UserWarning, match="brdf.npz"):
        out = assert_brdf_agrees("ts-vgroove", surface, AL, [30], cache=tmp_path, **TINY)
    assert out["passed"] and traces == [name]


def test_with_warnings_as_errors_the_damaged_entry_is_still_discarded(surface, good, tmp_path):
    root, name, brdf = good
    shutil.copytree(root / name, tmp_path / name)
    truncate(tmp_path / name / "brdf.npz")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(UserWarning, match="brdf.npz"):
            reference(surface, AL, [30], cache=tmp_path, **TINY)
        res = reference(surface, AL, [30], cache=tmp_path, **TINY)
    np.testing.assert_array_equal(res.brdf, brdf)


def test_a_reader_waits_for_the_worker_repairing_a_damaged_entry(surface, good, tmp_path, traces):
    """Another process holds the entry's lock (it found the entry damaged and is tracing it):
    this reader neither discards the entry nor traces it, and reads the repaired one."""
    root, name, brdf = good
    entry = tmp_path / name
    shutil.copytree(root / name, entry)
    truncate(entry / "brdf.npz")
    held, seen = threading.Event(), {}

    def other_worker():
        with atomic.output_lock(entry):
            held.set()
            time.sleep(0.5)
            seen["damaged entry kept"] = (entry / "brdf.npz").is_file()
            stage = atomic.make_staging(entry)
            shutil.rmtree(stage)
            shutil.copytree(root / name, stage)
            atomic.publish_dir(stage, entry)

    worker = threading.Thread(target=other_worker)
    worker.start()
    held.wait(10)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the repairing process reports it, not this one
        res = reference(surface, AL, [30], cache=tmp_path, **TINY)
    worker.join(10)
    assert seen == {"damaged entry kept": True}
    assert traces == []
    np.testing.assert_array_equal(res.brdf, brdf)


# --- what a user's BRDF returns ---------------------------------------------------------------
def ts(wi, wo):
    return torrance_sparrow(wi, wo, Beckmann(0.3), "vgroove", AL)


@pytest.mark.parametrize(
    "brdf, word",
    [
        (lambda wi, wo: ts(wi, wo) + 0j, "complex128"),
        (lambda wi, wo: ts(wi, wo) + 1e-3j, "complex128"),
        (lambda wi, wo: np.full(len(wo), "0.1"), "<U3"),
        (lambda wi, wo: ["0.1"] * len(wo), "<U3"),
        (lambda wi, wo: [0.1] * (len(wo) - 1) + [[0.1, 0.2]], "array"),
        (lambda wi, wo: ts(wi, wo) > 0, "bool"),
        (lambda wi, wo: None, "object"),
    ],
    ids=["complex", "complex-imag", "strings", "string-list", "ragged", "bool", "None"],
)
def test_a_brdf_returning_other_than_real_numbers_is_refused(brdf, word, surface, good):
    root, _, _ = good
    refused(
        lambda: assert_brdf_agrees(brdf, surface, AL, [30], cache=root, **TINY),
        "brdf(wi, wo)",
        "float64",
        "(N,)",
        word,
    )


# --- closed forms with mismatched shapes ------------------------------------------------------
UP5, UP4 = np.tile([0.0, 0.0, 1.0], (5, 1)), np.tile([0.0, 0.0, 1.0], (4, 1))


@pytest.mark.parametrize(
    "call, words",
    [
        (lambda: torrance_sparrow(UP5, UP4, GGX(0.3)), ("wi", "wo", "(5, 3)", "(4, 3)")),
        (lambda: torrance_sparrow(UP5, UP4, GGX(0.3), "smith"), ("wi", "wo", "(5, 3)")),
        (lambda: pdf_microfacet(UP5, UP4, GGX(0.3)), ("wi", "wo", "(5, 3)", "(4, 3)")),
        (
            lambda: sample_microfacet(UP5, np.zeros(4), np.zeros(4), GGX(0.3)),
            ("wo", "u1", "u2", "(5, 3)", "(4,)"),
        ),
        (
            lambda: sample_microfacet(UP5, np.zeros(5), np.zeros(3), GGX(0.3)),
            ("u1", "u2", "(5,)", "(3,)"),
        ),
        (
            lambda: mikkelsen_mix(
                UP5, UP4, AlbedoTable(GGX(0.3), n_theta=3, n_grazing=0, n_gl_phi=2), 0.5
            ),
            ("wi", "wo", "(5, 3)", "(4, 3)"),
        ),
    ],
    ids=["ts", "ts-smith", "pdf", "sample-wo", "sample-u", "mix"],
)
def test_closed_forms_name_arguments_whose_shapes_do_not_broadcast(call, words):
    refused(call, *words)


def test_closed_forms_still_broadcast_one_direction_against_many():
    f = torrance_sparrow(np.array([0.0, 0.0, 1.0]), UP4, GGX(0.3))
    assert f.shape == (4,)
    wi, pdf = sample_microfacet(UP4[0], np.full(4, 0.3), 0.7, GGX(0.3))
    assert wi.shape == (4, 3) and pdf.shape == (4,)


# --- sampler harness ---------------------------------------------------------------------------
def cosine(u1, u2):
    r, phi = np.sqrt(u1), 2 * np.pi * u2
    return np.stack([r * np.cos(phi), r * np.sin(phi), np.sqrt(1 - u1)], axis=1)


def cosine_pdf(w):
    return np.where(w[:, 2] > 0, w[:, 2] / np.pi, 0.0)


def nan_directions(u1, u2):
    return np.full((len(u1), 3), np.nan)


@pytest.mark.parametrize(
    "sample, pdf, kwargs, words",
    [
        (lambda a, b: cosine(a, b) + 0j, cosine_pdf, {}, ("sample(u1, u2)", "complex128")),
        (lambda a, b: np.full((len(a), 3), "x"), cosine_pdf, {}, ("sample(u1, u2)", "<U1")),
        (lambda a, b: [[0.0, 0.0, 1.0]] * (len(a) - 1) + [[0.0]], cosine_pdf, {}, ("sample",)),
        (cosine, lambda w: cosine_pdf(w) + 0j, {}, ("pdf(w)", "complex128")),
        (cosine, lambda w: np.full(len(w), "x"), {}, ("pdf(w)", "<U1")),
        (lambda a, b: (cosine(a, b), np.full(len(a), "x")), cosine_pdf, {}, ("pdf values",)),
        (lambda a, b: (cosine(a, b), cosine_pdf(cosine(a, b)) + 0j), cosine_pdf, {}, ("pdf",)),
        (nan_directions, lambda w: np.zeros(len(w)), {}, ("sample", "nothing to test")),
        (cosine, cosine_pdf, dict(min_expected=None), ("min_expected",)),
        (cosine, cosine_pdf, dict(min_expected=np.nan), ("min_expected",)),
        (cosine, cosine_pdf, dict(min_expected=-1), ("min_expected",)),
        (cosine, cosine_pdf, dict(pdf_rtol=None), ("pdf_rtol",)),
        (cosine, cosine_pdf, dict(pdf_rtol=np.nan), ("pdf_rtol",)),
    ],
    ids=[
        "complex-directions",
        "string-directions",
        "ragged-directions",
        "complex-pdf",
        "string-pdf",
        "string-pdf-values",
        "complex-pdf-values",
        "all-rejected-zero-pdf",
        "min_expected-None",
        "min_expected-nan",
        "min_expected-negative",
        "pdf_rtol-None",
        "pdf_rtol-nan",
    ],
)
def test_sampler_harness_refuses_bad_returns_and_arguments(sample, pdf, kwargs, words):
    refused(lambda: assert_sampler_matches(sample, pdf, n=10_000, **kwargs), *words)


def test_a_sampler_rejecting_every_sample_fails_as_an_assertion():
    with pytest.raises(AssertionError, match="outside"):
        assert_sampler_matches(nan_directions, cosine_pdf, n=10_000)


@pytest.mark.parametrize(
    "observed, expected, word",
    [
        ([np.nan, 1.0], [1.0, 1.0], "observed"),
        ([1.0, 1.0], [np.nan, 1.0], "expected"),
        ([-1.0, 3.0], [1.0, 1.0], "observed"),
        ([1.0, 1.0], [-1.0, 3.0], "expected"),
        ([1.0, 1.0, 1.0], [1.0, 2.0], "same number of cells"),
        (["a", "b"], [1.0, 1.0], "observed"),
    ],
)
def test_pearson_chi2_refuses_counts_that_are_not_finite_and_nonnegative(observed, expected, word):
    refused(lambda: pearson_chi2(observed, expected), word)
