"""This process's cgroup memory limit is read once; any other cgroup tree is read every time."""

from pathlib import Path


def test_the_own_cgroup_limit_is_read_once_and_a_given_tree_every_time(tmp_path, monkeypatch):
    """memory_limit() is asked for every level a solve meshes: the files of this process's
    own cgroup (the default paths) are read on the first call only and the same limit comes
    back; a tree given by path (a container's, a test's) is read on every call, so that a
    changed file is seen."""
    import contactfem.estimate as estimate

    reads: list[tuple[Path, Path]] = []
    real = estimate._read_cgroup_limit

    def counted(proc: Path, cgroups: Path) -> int | None:
        reads.append((proc, cgroups))
        return real(proc, cgroups)

    monkeypatch.setattr(estimate, "_read_cgroup_limit", counted)
    monkeypatch.setattr(estimate, "_OWN_CGROUP", {})
    monkeypatch.setattr(estimate, "_address_space_limit", lambda: None)
    first = estimate.memory_limit()
    assert estimate.memory_limit() == first and estimate.memory_limit() == first
    assert reads == [estimate._OWN_PATHS]

    proc, cgroups = tmp_path / "proc", tmp_path / "cgroup"
    (proc).mkdir()
    (cgroups / "job").mkdir(parents=True)
    (proc / "cgroup").write_text("0::/job\n", encoding="ascii")
    (cgroups / "job" / "memory.max").write_text(f"{2**30}\n", encoding="ascii")
    assert estimate.memory_limit(proc, cgroups).bytes == min(2**30, estimate.machine_memory())
    (cgroups / "job" / "memory.max").write_text(f"{2**29}\n", encoding="ascii")
    assert estimate.memory_limit(proc, cgroups).bytes == min(2**29, estimate.machine_memory())
    assert reads[1:] == [(proc, cgroups), (proc, cgroups)]
