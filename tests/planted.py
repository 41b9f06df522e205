"""A fault planted in an exported model: the output folder copied (its files linked) with
mechanism.xml edited, and what `linkd verify` says of the collision it must find."""

import xml.etree.ElementTree as ET
from pathlib import Path

from linkd.verify import verify_output


def editable_copy(out: Path, to: Path) -> tuple[ET.ElementTree, dict[str, ET.Element]]:
    """Every file of `out` linked into `to` but mechanism.xml, whose tree is returned to edit,
    with its geoms by name."""
    for path in out.iterdir():
        if path.name != "mechanism.xml":
            (to / path.name).symlink_to(path)
    tree = ET.parse(out / "mechanism.xml")
    return tree, {geom.get("name"): geom for geom in tree.iter("geom")}


def collision_detail(tree: ET.ElementTree, folder: Path) -> str:
    """Write the edited model into `folder`, verify it, and say what the collision check, which
    must fail, reports."""
    tree.write(folder / "mechanism.xml")
    report = verify_output(folder, write=False)
    assert "collisions" in report.failed
    return next(check.detail for check in report.checks if check.name == "collisions")
