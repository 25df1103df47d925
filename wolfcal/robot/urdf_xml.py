"""The one strict URDF parser (lxml) of every URDF reader and writer."""

from __future__ import annotations

from pathlib import Path

from lxml import etree

from wolfcal.errors import WolfcalError


def read_urdf_xml(urdf_path: str | Path) -> etree._ElementTree:
    """Parse a URDF strictly (well-formed XML, root <robot>; entities are never expanded): the one parser of
    every reader and writer, so a file that loads also writes back."""
    urdf_path = Path(urdf_path)
    parser = etree.XMLParser(
        remove_blank_text=False, remove_comments=False, resolve_entities=False, no_network=True, load_dtd=False
    )
    try:
        tree = etree.parse(str(urdf_path), parser)
    except OSError as exc:
        raise WolfcalError(f"{urdf_path}: cannot read the URDF ({exc})") from None
    except etree.XMLSyntaxError as exc:
        raise WolfcalError(
            f"{urdf_path}: not a well-formed URDF: {exc.msg} (line {exc.lineno}); fix the XML of this file"
        ) from None
    if tree.getroot().tag != "robot":
        raise WolfcalError(f"{urdf_path}: the root element is <{tree.getroot().tag}>, a URDF's is <robot>")
    return tree
