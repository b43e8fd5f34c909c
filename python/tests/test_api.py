"""volao from Python against the volao CLI: the same bytes for the same scene, the same
AO volume, numpy and nibabel input equal to file input, one clear exception per bad
input."""

from __future__ import annotations

import logging

import nibabel as nib
import numpy as np
import pytest

import volao
from conftest import read_png, run_cli

AVG152 = "nifti/avg152T1_LR_nifti.nii.gz"  # 91×109×91 u8, LAS: flipped on the way to RAS


def small_scene(volume, **extra):
    settings = dict(tf="mr-t1-brain", ao="lao", rays=14, samples=6, width=72, height=64,
                    camera=(30.0, 15.0, 3.0))
    settings.update(extra)
    return volao.Scene(volume, **settings)


def test_render_equals_the_cli_byte_for_byte(data, volao_cli, tmp_path):
    scene = small_scene(volao.load(data / AVG152), shading="phong")
    image = scene.render()
    assert isinstance(image, np.ndarray) and isinstance(image, volao.Image)
    assert image.shape == (64, 72, 4) and image.dtype == np.uint8
    assert image[..., 3].max() == 255, "something was drawn"
    scene.save(tmp_path / "s.json")
    run_cli(volao_cli, "render", tmp_path / "s.json", "-o", tmp_path / "cli.png")
    assert np.array_equal(read_png(tmp_path / "cli.png"), image), "every byte as the CLI"
    image.save(tmp_path / "py.png")
    assert (tmp_path / "py.png").read_bytes() == (tmp_path / "cli.png").read_bytes()
    assert read_png_bytes(image._repr_png_()).tolist() == image.tolist()
    # The saved scene, read back, renders the same again.
    again = volao.Scene.load(tmp_path / "s.json").render()
    assert np.array_equal(again, image)


def read_png_bytes(png: bytes) -> np.ndarray:
    import tempfile, os
    with tempfile.NamedTemporaryFile(suffix=".png", delete=False) as f:
        f.write(png)
    try:
        return read_png(f.name)
    finally:
        os.unlink(f.name)


def test_render_size_and_settings_override_the_scene(data, volao_cli, tmp_path):
    scene = small_scene(volao.load(data / "pvm/Bucky.pvm"), tf="ct-bone", ao="none")
    scene.set(mode="mip", background=[0.0, 0.0, 0.0, 0.0], window_level=(200, 100))
    image = scene.render(40, 30)
    assert image.shape == (30, 40, 4)
    scene.save(tmp_path / "mip.json")
    run_cli(volao_cli, "render", tmp_path / "mip.json", "--width", "40", "--height", "30",
            "-o", tmp_path / "mip.png")
    assert np.array_equal(read_png(tmp_path / "mip.png"), image)
    assert '"mode": "mip"' in scene.to_json()


def test_numpy_input_equals_file_input(data):
    loaded = volao.load(data / AVG152)
    expected = small_scene(loaded).render()
    array = loaded.array
    assert array.shape == loaded.dims and array.flags.f_contiguous
    for copy in (array, np.ascontiguousarray(array), array[:, ::-1, :][:, ::-1, :]):
        volume = volao.Volume(copy, affine=loaded.affine)
        assert volume.dims == loaded.dims and volume.spacing == loaded.spacing
        assert np.array_equal(volume.array, array)
        assert np.array_equal(small_scene(volume).render(), expected), "C, F and strided alike"


def test_nibabel_round_trip(data, tmp_path):
    image = nib.load(data / AVG152)
    volume = volao.Volume(image)
    loaded = volao.load(data / AVG152)
    assert volume.dims == loaded.dims == image.shape
    assert volume.dtype == loaded.dtype == "uint8"
    assert np.allclose(volume.spacing, image.header.get_zooms())
    assert np.array_equal(volume.array, np.asanyarray(image.dataobj))
    assert np.array_equal(volume.array, loaded.array)
    assert np.allclose(volume.affine, image.affine) and np.allclose(loaded.affine, image.affine)
    back = volume.to_nibabel()
    assert np.array_equal(np.asanyarray(back.dataobj), np.asanyarray(image.dataobj))
    assert np.allclose(back.affine, image.affine)
    nib.save(back, tmp_path / "back.nii.gz")
    again = volao.load(tmp_path / "back.nii.gz")
    assert np.array_equal(again.array, loaded.array) and np.allclose(again.affine, loaded.affine)
    volume.save(tmp_path / "volao.nii.gz")
    written = nib.load(tmp_path / "volao.nii.gz")
    assert np.array_equal(np.asanyarray(written.dataobj), np.asanyarray(image.dataobj))
    assert np.allclose(written.affine, image.affine)


@pytest.mark.parametrize("method,flags,settings", [
    ("lao", ["--rays", "14", "--samples", "6"], {"rays": 14, "samples": 6}),
    ("cdf", ["--radius", "3"], {"radius": 3.0}),
])
def test_ambient_occlusion_equals_volao_ao(data, volao_cli, tmp_path, method, flags, settings):
    path = data / AVG152
    out = tmp_path / "ao.nii.gz"
    run_cli(volao_cli, "ao", path, "-o", out, "--method", method, *flags)
    expected = np.asanyarray(nib.load(out).dataobj)
    assert expected.dtype == np.float32
    ao = volao.ambient_occlusion(volao.load(path), method=method, **settings)
    assert ao.dtype == np.float32 and ao.shape == expected.shape
    assert np.array_equal(ao, expected), "every voxel as volao ao"
    assert 0.0 <= ao.min() < 1.0 and ao.max() <= 1.0


def test_a_bad_path_is_one_clear_exception(data):
    with pytest.raises(FileNotFoundError, match="no-such-file.nii"):
        volao.load(data / "no-such-file.nii")
    with pytest.raises(volao.VolaoError, match="not-nifti.nii"):
        volao.load(data / "nifti/not-nifti.nii")


def test_a_1d_array_is_one_clear_exception():
    with pytest.raises(ValueError, match=r"1 dimension .* a volume needs 3"):
        volao.Volume(np.zeros(10, dtype=np.float32))


def test_an_unsupported_dtype_is_one_clear_exception():
    with pytest.raises(TypeError, match="unsupported dtype .*int64|unsupported dtype <i8"):
        volao.Volume(np.zeros((4, 4, 4), dtype=np.int64))
    with pytest.raises(TypeError, match="unsupported dtype"):
        volao.Volume(np.zeros((4, 4, 4), dtype=np.complex64))


def test_bad_settings_are_clear_exceptions(data):
    bucky = volao.load(data / "pvm/Bucky.pvm")
    with pytest.raises(TypeError, match='unknown setting "colour"'):
        volao.Scene(bucky, colour="red")
    with pytest.raises(volao.VolaoError, match="unknown variant"):
        volao.Scene(bucky, ao="magic")
    with pytest.raises(ValueError, match="render mode"):
        volao.Scene(bucky, mode="sideways")
    with pytest.raises(volao.VolaoError, match="has no file"):
        volao.Scene(volao.Volume(bucky.array)).save("never.json")


def test_notes_go_to_logging_and_progress_to_the_callback(data, caplog, capfd):
    calls = []
    with caplog.at_level(logging.INFO, logger="volao"):
        small_scene(volao.load(data / "pvm/Bucky.pvm")).render(
            progress=lambda stage, done, total: calls.append((stage, done, total)))
    assert any("rendered 72×64" in r.getMessage() for r in caplog.records)
    assert calls and calls[-1][1] == calls[-1][2], "progress reaches its total"
    assert capfd.readouterr().out == "", "nothing printed"


def test_a_raising_progress_callback_is_raised_after_the_call(data):
    def boom(stage, done, total):
        raise RuntimeError("stop here")

    with pytest.raises(RuntimeError, match="stop here"):
        volao.ambient_occlusion(volao.load(data / "pvm/Bucky.pvm"), rays=6, samples=2,
                                progress=boom)
