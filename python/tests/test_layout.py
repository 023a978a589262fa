"""The package layout: the Python sources live in python/python/cantwin (maturin's
`python-source = "python"`), so that running pytest inside python/ imports the installed
package, never a source folder that lacks the native module."""

from pathlib import Path

import cantwin
import cantwin._native

PROJECT = Path(__file__).resolve().parents[1]


def test_no_source_folder_can_shadow_the_installed_package():
    # pytest puts the directory it runs in on sys.path: a `cantwin` folder there would be
    # imported in place of the installed package.
    assert not (PROJECT / "cantwin").exists()
    assert (PROJECT / "python" / "cantwin" / "__init__.py").is_file()


def test_the_imported_package_has_its_native_module():
    assert cantwin._native.__name__ == "cantwin._native"
    assert Path(cantwin.__file__).resolve().parent != PROJECT / "cantwin"
