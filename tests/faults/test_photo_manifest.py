"""Bad photo manifests (photos app, `photos_manifest`): one line naming the manifest, the row/column, the fix."""

import pytest

from palpation.markers.manifest import read_manifest


@pytest.fixture
def photos(tmp_path):
    folder = tmp_path / "photos"
    folder.mkdir()
    (folder / "a.jpg").write_bytes(b"")
    return folder


def write(tmp_path, text, name="manifest.csv"):
    path = tmp_path / name
    path.write_text(text)
    return path


def test_manifest_missing_column(tmp_path, photos, fault):
    """a photo manifest without the `depth` column"""
    path = write(tmp_path, "file,kind,angle\na.jpg,press,\n")
    with fault(ValueError, str(path), "column 'depth' missing", "file, kind, depth, angle"):
        read_manifest(path, photos)


def test_manifest_unknown_kind(tmp_path, photos, fault):
    """a photo manifest row whose kind is not a trajectory"""
    path = write(tmp_path, "file,kind,depth,angle\na.jpg,pres,2,\n")
    with fault(ValueError, str(path), "row 1 column 'kind'", "'pres'", "press, twist_z"):
        read_manifest(path, photos)


def test_manifest_bad_depth(tmp_path, photos, fault):
    """a photo manifest row whose depth is not a number"""
    path = write(tmp_path, "file,kind,depth,angle\na.jpg,press,deep,\n")
    with fault(ValueError, str(path), "row 1 column 'depth'", "'deep'", "depth in mm"):
        read_manifest(path, photos)


def test_manifest_missing_photo(tmp_path, photos, fault):
    """a photo manifest naming a photo that is not in photos_dir"""
    path = write(tmp_path, "file,kind,depth,angle\nb.jpg,press,2,\n")
    with fault(FileNotFoundError, str(path), "column 'file'", "b.jpg", "relative to photos_dir"):
        read_manifest(path, photos)


def test_manifest_broken_yaml(tmp_path, photos, fault):
    """a YAML photo manifest that does not parse"""
    path = write(tmp_path, "photos: [ {file: a.jpg, kind: press\n", name="manifest.yaml")
    with fault(ValueError, str(path), "cannot parse it", "file, kind, depth, angle"):
        read_manifest(path, photos)


def test_manifest_does_not_exist(tmp_path, photos, fault):
    """photos_manifest pointing at no file"""
    with fault(FileNotFoundError, "nope.csv", "photos_manifest", "docs/measured_format.md"):
        read_manifest(tmp_path / "nope.csv", photos)


def test_manifest_unknown_format(tmp_path, photos, fault):
    """a photo manifest that is neither CSV nor YAML"""
    path = write(tmp_path, "file kind depth angle\n", name="manifest.txt")
    with fault(ValueError, str(path), "'.txt'", "use .csv, .yaml or .yml"):
        read_manifest(path, photos)


def test_gpu_checks_without_cached_mesh(tmp_path, fault):
    """workflow/scripts/gpu_twin_checks.sh on a machine without the cached meshes"""
    import subprocess

    from palpation.paths import REPO_ROOT

    out = subprocess.run(["bash", str(REPO_ROOT / "workflow/scripts/gpu_twin_checks.sh"), str(tmp_path / "o")],
                         cwd=REPO_ROOT, env={"PATH": "/usr/bin:/bin", "MESH_DIR": str(tmp_path)},
                         capture_output=True, text=True, timeout=30)
    with fault(SystemExit, "mesh_coarse.npz missing", "snakemake results/twin/mesh_coarse.npz", "MESH_DIR"):
        if out.returncode:
            raise SystemExit(out.stderr.strip())
