"""numba's cache on a read-only install: the package falls back to a private temporary directory, or to no cache.

The end-to-end cases copy the package into a read-only directory and run ``make("navigation")`` in a
subprocess of an unprivileged user whose home directory does not exist, so that numba finds neither a
writable ``__pycache__`` next to the sources nor a user-wide cache directory. Running as root, write
permissions are not enforced, so the subprocess then runs as ``nobody`` through ``setpriv``; where that is
not possible the cases are skipped (a simulation would only test the simulation).
"""

from __future__ import annotations

import os
import shutil
import stat
import subprocess
import sys
import tempfile
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest

import agentsim_env
from agentsim_env import _numba_cache
from agentsim_env._numba_cache import FALLBACK_PREFIX, ensure_numba_cache, in_tree_writable, private_dir

pytestmark = pytest.mark.skipif(not hasattr(os, "geteuid"), reason="POSIX permissions")

FALLBACK_WARNING = "agentsim_env: numba cannot cache kernels"
UNCACHED_WARNING = "agentsim_env: no writable directory for numba's cache"

# Prints the cache directory in use at the end; the package must come from the read-only copy.
SCRIPT = """
import os, sys, tempfile
if len(sys.argv) > 1:
    tempfile.tempdir = sys.argv[1]  # what tempfile.gettempdir() answers
if os.environ.get("IMPORT_NUMBA_FIRST"):
    import numba  # numba has read its configuration already
import agentsim_env
assert agentsim_env.__file__.startswith(os.environ["PYTHONPATH"]), agentsim_env.__file__
env = agentsim_env.make("navigation", n_agents=2)
env.reset(seed=0)
print("NUMBA_CACHE_DIR=" + os.environ.get("NUMBA_CACHE_DIR", ""))
"""


@dataclass(frozen=True)
class ReadOnlyInstall:
    """A read-only copy of the package and how to run Python on it as a user who cannot write there."""

    site: Path  # holds the copy; read-only
    tmp: Path  # writable by the user (sticky, like /tmp)
    prefix: tuple[str, ...]  # command prefix that drops privileges (empty when not root)
    uid: int

    def run(self, env: dict[str, str], *args: str) -> subprocess.CompletedProcess[str]:
        """Run ``SCRIPT`` with ``env`` on top of a clean environment (no cache settings, home missing)."""
        base = {k: v for k, v in os.environ.items() if k not in ("NUMBA_CACHE_DIR", "XDG_CACHE_HOME")}
        base = {k: v for k, v in base.items() if not k.startswith(("NUMBA_CACHE", "PYTHON"))}
        base |= {
            "HOME": str(self.site / "no-home"),
            "TMPDIR": str(self.tmp),
            "PYTHONPATH": str(self.site),
            "PYTHONWARNINGS": "default",
            "PYTHONDONTWRITEBYTECODE": "1",
        }
        return subprocess.run(
            [*self.prefix, sys.executable, "-c", SCRIPT, *args],
            env=base | env,
            cwd=self.site.parent,  # not the repository: "-c" puts the working directory first on sys.path
            capture_output=True,
            text=True,
            timeout=180,
        )


def _drop_privileges() -> tuple[tuple[str, ...], int]:
    if os.geteuid() != 0:
        return (), os.getuid()
    import pwd

    setpriv = shutil.which("setpriv")
    try:
        nobody = pwd.getpwnam("nobody")
    except KeyError:
        pytest.skip("running as root without a 'nobody' user to drop to")
    if setpriv is None:
        pytest.skip("running as root without setpriv to drop privileges")
    prefix = (setpriv, f"--reuid={nobody.pw_uid}", f"--regid={nobody.pw_gid}", "--clear-groups")
    probe = subprocess.run([*prefix, sys.executable, "-c", "import numba"], capture_output=True, timeout=60)
    if probe.returncode != 0:
        pytest.skip(f"user 'nobody' cannot run this Python: {probe.stderr.decode(errors='replace')[-200:]}")
    return prefix, nobody.pw_uid


@pytest.fixture(scope="module")
def install() -> Iterator[ReadOnlyInstall]:
    prefix, uid = _drop_privileges()
    root = Path(tempfile.mkdtemp(prefix="agentsim-ro-"))
    try:
        root.chmod(0o755)  # pytest's tmp_path is private to its owner
        site, tmp = root / "site", root / "tmp"
        src = Path(agentsim_env.__file__).parent
        shutil.copytree(src, site / "agentsim_env", ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))
        tmp.mkdir()
        tmp.chmod(0o1777)
        for d, _, files in os.walk(site):
            for f in files:
                os.chmod(os.path.join(d, f), 0o444)
            os.chmod(d, 0o555)
        yield ReadOnlyInstall(site, tmp, prefix, uid)
    finally:
        for d, _, _ in os.walk(root):
            os.chmod(d, 0o755)
        shutil.rmtree(root, ignore_errors=True)


def _ok(res: subprocess.CompletedProcess[str]) -> str:
    assert res.returncode == 0, res.stderr[-3000:]
    return res.stdout.strip().splitlines()[-1].removeprefix("NUMBA_CACHE_DIR=")


def test_read_only_install_falls_back_to_a_private_temporary_cache(install: ReadOnlyInstall) -> None:
    res = install.run({})
    cache = _ok(res)
    assert cache == str(install.tmp / f"{FALLBACK_PREFIX}{install.uid}")
    assert res.stderr.count(FALLBACK_WARNING) == 1 and UNCACHED_WARNING not in res.stderr
    (line,) = [ln for ln in res.stderr.splitlines() if FALLBACK_WARNING in ln]
    assert cache in line and "NUMBA_CACHE_DIR" in line
    st = os.stat(cache)
    assert st.st_uid == install.uid and stat.S_IMODE(st.st_mode) == 0o700
    assert list(Path(cache).rglob("*.nbi")), "nothing was cached"
    # the same when numba was imported first (numba.config.CACHE_DIR is set along with the variable)
    res = install.run({"IMPORT_NUMBA_FIRST": "1"})
    assert _ok(res) == cache and res.stderr.count(FALLBACK_WARNING) == 1
    # an existing NUMBA_CACHE_DIR is respected as is: no warning (and the kernels load from that cache)
    res = install.run({"NUMBA_CACHE_DIR": cache})
    assert _ok(res) == cache and "agentsim_env:" not in res.stderr


def test_read_only_install_uses_a_writable_home_without_warning(install: ReadOnlyInstall) -> None:
    home = install.tmp / "home"
    res = install.run({"HOME": str(home)})
    assert _ok(res) == "" and "agentsim_env:" not in res.stderr
    assert list((home / ".cache" / "numba").rglob("*.nbi")), "numba's user-wide cache was not used"


def test_read_only_install_without_any_writable_directory_compiles_uncached(install: ReadOnlyInstall) -> None:
    res = install.run({}, str(install.site))  # the temporary directory is read-only too
    assert _ok(res) == ""
    assert res.stderr.count(UNCACHED_WARNING) == 1 and FALLBACK_WARNING not in res.stderr


def test_writable_install_is_left_alone(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    if not in_tree_writable():
        pytest.skip("this checkout is read-only")
    before = os.environ.get("NUMBA_CACHE_DIR")
    assert ensure_numba_cache() is None
    assert os.environ.get("NUMBA_CACHE_DIR") == before


def test_existing_setting_is_respected(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("NUMBA_CACHE_DIR", "/some/where")
    monkeypatch.setattr(_numba_cache, "in_tree_writable", lambda root: pytest.fail("checked the tree"))
    assert ensure_numba_cache() is None and os.environ["NUMBA_CACHE_DIR"] == "/some/where"


def test_private_dir_is_created_private_and_reused(tmp_path: Path) -> None:
    path = private_dir(str(tmp_path))
    assert path is not None and stat.S_IMODE(os.stat(path).st_mode) == 0o700
    assert private_dir(str(tmp_path)) == path


def test_private_dir_refuses_a_directory_others_may_write(tmp_path: Path) -> None:
    path = tmp_path / f"{FALLBACK_PREFIX}{os.getuid()}"
    path.mkdir()
    path.chmod(0o777)  # another user could plant cache files, which numba unpickles
    assert private_dir(str(tmp_path)) is None
    path.chmod(0o700)
    assert private_dir(str(tmp_path)) == str(path)
    path.rmdir()
    path.symlink_to(tmp_path)
    assert private_dir(str(tmp_path)) is None
