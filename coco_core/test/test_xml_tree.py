"""The line-keeping XML tree under the loader."""

import pytest

from coco_core.errors import ConfigError
from coco_core.xml.tree import parse_xml


def test_every_element_knows_its_line_and_text():
    root = parse_xml(b'<package>\n  <paths>\n    <path\n      x="1">a<!-- c -->b</path>\n  </paths>\n</package>', "f.xml")
    (paths,) = root.children
    (path,) = paths.children
    assert (root.tag, root.location.file, root.location.line) == ("package", "f.xml", 1)
    assert paths.location.line == 2
    assert path.location.line == 3  # where the start tag opens
    assert path.attributes == {"x": "1"}
    assert path.text == "ab"
    assert paths.text.strip() == ""


def test_encoding_declaration_is_honoured():
    root = parse_xml('<?xml version="1.0" encoding="ISO-8859-1"?><p a="\xe9"/>'.encode("latin-1"), "f")
    assert root.attributes == {"a": "\xe9"}


@pytest.mark.parametrize(
    ("text", "line", "message"),
    [
        ("<a>\n<b>\n</a>", 3, "mismatched tag"),
        ("", 1, "no element found"),
        ("<a/>\n<b/>", 2, "junk after document element"),
        ('<a x="1" x="2"/>', 1, "duplicate attribute"),
        ("<a>&nope;</a>", 1, "undefined entity"),
    ],
)
def test_syntax_errors_point_at_their_line(text, line, message):
    with pytest.raises(ConfigError) as raised:
        parse_xml(text, "bad.xml")
    assert raised.value.location is not None
    assert (raised.value.location.file, raised.value.location.line) == ("bad.xml", line)
    assert raised.value.message.startswith(f"XML syntax error: {message}")
