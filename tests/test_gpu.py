"""The GPU path: physics, metrics and renderer on CUDA / NVIDIA EGL against the CPU.

Every test here is marked ``gpu`` and skips, saying why, on a machine without a CUDA device
(``warp.is_cuda_available()``) or without NVIDIA's EGL (the vendor string of an EGL
context). Tolerances, stated per test:

* physics (``correct`` on CUDA vs CPU, the study's D1 concert with the mannequins, 0.5 s):
  the CUDA run sums its contacts in a different order (atomics) and, by default, solves
  with ``warp.optim.linear.cg`` instead of the fused CPU PCG, both to the same relative
  residual (1e-4 here, tighter than the default 1e-3, so that the two runs differ by the
  order of their sums rather than by where two solvers stop): mean joint distance between
  the two results <= 0.5 cm, largest <= 3 cm; with the same (fused) PCG on CUDA <= 0.2 cm
  mean; the tracking error of each against the Baseline within 0.3 cm of the other;
* metrics (mesh overlap, Warp on CUDA vs Warp on the CPU, float64 kernels): relative
  1e-6 per character and frame (absolute 1e-12 m^3);
* renderer (the same frame through NVIDIA's EGL and Mesa's llvmpipe, 320x180, 4x MSAA,
  shadows): PSNR >= 30 dB (the two rasterisers place MSAA samples and filter shadows
  differently; a missing or misplaced character costs far more).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pytestmark = pytest.mark.gpu

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
EGL_VENDOR_DIRS = (Path("/usr/share/glvnd/egl_vendor.d"), Path("/etc/glvnd/egl_vendor.d"))


def _require_cuda() -> str:
    from crowdstudy.warp_runtime import get_warp

    wp = get_warp()
    if not wp.is_cuda_available():
        pytest.skip("no CUDA device (warp.is_cuda_available() is False): the GPU path is not tested here")
    return "cuda:0"


@pytest.fixture(scope="module")
def cuda_device() -> str:
    return _require_cuda()


@pytest.fixture(scope="module")
def d1_concert(cuda_device):
    from crowdstudy.design import load_design
    from crowdstudy.motion.baseline import build_baseline

    return build_baseline(load_design(), "stationary", "D1", duration=0.5, body_model="open")


@pytest.fixture(scope="module")
def cpu_corrected(d1_concert):
    from crowdstudy.physics.corrector import correct

    return correct(d1_concert, device="cpu", progress=False, config=_tight())


def _tight():
    """The physics comparison's config, on both sides: CG to 1e-4 (the default stops at 1e-3)."""
    from crowdstudy.physics import PhysicsConfig

    return PhysicsConfig().with_values(cg_tolerance=1e-4)


def _joint_distance_cm(a, b) -> tuple[float, float]:
    """Mean and largest distance (cm) between the joints of two animations of one crowd."""
    from crowdstudy.metrics.tracking import joint_positions

    d = np.linalg.norm(joint_positions(a) - joint_positions(b), axis=-1)
    return 100.0 * float(d.mean()), 100.0 * float(d.max())


@pytest.mark.parametrize("linear_solver,mean_cm", [(None, 0.5), ("fused", 0.2)])
def test_physics_on_cuda_matches_the_cpu(cuda_device, d1_concert, cpu_corrected, linear_solver, mean_cm):
    device = cuda_device
    from crowdstudy.metrics import tracking_error
    from crowdstudy.physics.corrector import correct

    gpu = correct(d1_concert, device=device, progress=False, linear_solver=linear_solver, config=_tight())
    assert gpu.meta["physics"]["device"] == device
    assert np.all(np.isfinite(gpu.root_translation)) and np.all(np.isfinite(gpu.joint_rotations))
    mean, largest = _joint_distance_cm(gpu, cpu_corrected)
    assert mean <= mean_cm and largest <= 3.0, (mean, largest)
    track_gpu, track_cpu = tracking_error(gpu, d1_concert), tracking_error(cpu_corrected, d1_concert)
    assert abs(track_gpu - track_cpu) <= 0.3, (track_gpu, track_cpu)


def test_mesh_overlap_on_cuda_matches_the_cpu(cuda_device, d1_concert, cpu_corrected):
    device = cuda_device
    from crowdstudy.metrics import overlap_volume

    for anim in (d1_concert, cpu_corrected):
        frames = [0, anim.n_frames // 2, anim.n_frames - 1]
        on_cpu = overlap_volume(anim, geometry="mesh", frames=frames, device="cpu")
        on_gpu = overlap_volume(anim, geometry="mesh", frames=frames, device=device)
        assert on_cpu.per_character.sum() > 0.0  # the D1 Baseline has contacts to measure
        np.testing.assert_allclose(on_gpu.per_character, on_cpu.per_character, rtol=1e-6, atol=1e-12)


_RENDER_SCRIPT = r"""
import json, sys
import numpy as np
sys.path.insert(0, sys.argv[1])
from render_fixtures import crowd_animation, grid_positions, mannequin_loader
from crowdstudy.design import load_design
from crowdstudy.render.context import context_info
from crowdstudy.render.renderer import CrowdRenderer

anim = crowd_animation(grid_positions(12, seed=3), n_frames=3)
with CrowdRenderer(anim, design=load_design(), width=320, height=180, msaa=4, shadows=True,
                   body_loader=mannequin_loader) as r:
    r.set_view("V3")
    image = r.render(1)
np.save(sys.argv[2], image)
print(json.dumps(context_info()))
"""


def _vendor_file(name: str) -> Path | None:
    for folder in EGL_VENDOR_DIRS:
        for path in sorted(folder.glob(f"*{name}*.json")) if folder.is_dir() else []:
            return path
    return None


def _render_with(vendor_json: Path, out: Path) -> dict:
    env = dict(os.environ, __EGL_VENDOR_LIBRARY_FILENAMES=str(vendor_json), PYTHONPATH=str(ROOT))
    proc = subprocess.run(
        [sys.executable, "-c", _RENDER_SCRIPT, str(HERE), str(out)],
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
    )
    if proc.returncode != 0:
        return {"error": proc.stderr.strip().splitlines()[-1] if proc.stderr.strip() else f"exit {proc.returncode}"}
    return json.loads(proc.stdout.strip().splitlines()[-1])


def test_renderer_on_nvidia_egl_matches_llvmpipe(tmp_path):
    nvidia = _vendor_file("nvidia")
    if nvidia is None:
        pytest.skip(
            "no NVIDIA EGL vendor library (no glvnd egl_vendor.d/*nvidia*.json): the GPU renderer is not tested here"
        )
    mesa = _vendor_file("mesa")
    if mesa is None:
        pytest.skip("no Mesa EGL vendor library (egl_vendor.d/*mesa*.json) to compare against")
    info_gpu = _render_with(nvidia, tmp_path / "nvidia.npy")
    vendor = (info_gpu.get("vendor", "") + " " + info_gpu.get("renderer", "")).lower()
    if "error" in info_gpu or "nvidia" not in vendor:
        pytest.skip(f"NVIDIA EGL gives no NVIDIA context here ({info_gpu}): the GPU renderer is not tested")
    info_cpu = _render_with(mesa, tmp_path / "mesa.npy")
    assert "error" not in info_cpu and "llvmpipe" in info_cpu["renderer"].lower(), info_cpu
    a = np.load(tmp_path / "nvidia.npy").astype(np.float64)
    b = np.load(tmp_path / "mesa.npy").astype(np.float64)
    assert a.shape == b.shape == (180, 320, 3)
    mse = float(np.mean((a - b) ** 2))
    psnr = float("inf") if mse == 0 else 10.0 * np.log10(255.0**2 / mse)
    assert psnr >= 30.0, (psnr, info_gpu, info_cpu)
    assert a.std() > 5.0  # a real picture (characters on a lit floor), not a blank
