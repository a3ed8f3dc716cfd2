"""Parse XML text into a small element tree that remembers the line of every element.

``xml.etree`` forgets where an element came from, and every error the loader reports must point at
a file and a line, so the tree is built here from expat's events. The tree is deliberately plain:
tag, attributes, children, text and location; what the elements mean is the loader's business.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from xml.parsers import expat

from ..errors import ConfigError, Location


@dataclass
class Element:
    """One XML element and where it starts."""

    tag: str
    attributes: dict[str, str]
    location: Location
    children: list["Element"] = field(default_factory=list)
    text: str = ""
    """All character data directly inside this element, including what stands between children, so
    that stray text in a container element can be reported."""


def parse_xml(data: bytes | str, file: str) -> Element:
    """Build the tree of ``data``; a syntax error becomes a :class:`ConfigError` at its line.

    Bytes are decoded by expat according to the XML declaration; text is taken as already decoded.
    A declared encoding that cannot be decoded is an error at the declaration's line.
    """
    parser = expat.ParserCreate()
    parser.buffer_text = True
    open_elements: list[Element] = []
    texts: list[list[str]] = []
    roots: list[Element] = []

    def start(tag: str, attributes: dict[str, str]) -> None:
        element = Element(tag, attributes, Location(file, parser.CurrentLineNumber))
        (open_elements[-1].children if open_elements else roots).append(element)
        open_elements.append(element)
        texts.append([])

    def end(_tag: str) -> None:
        open_elements.pop().text = "".join(texts.pop())

    def character_data(text: str) -> None:
        if texts:
            texts[-1].append(text)

    parser.StartElementHandler = start
    parser.EndElementHandler = end
    parser.CharacterDataHandler = character_data
    try:
        parser.Parse(data, True)
    except expat.ExpatError as error:
        message = expat.errors.messages[error.code]
        raise ConfigError(
            f"XML syntax error: {message} (column {error.offset + 1})", Location(file, error.lineno)
        ) from None
    except (LookupError, ValueError) as error:
        # pyexpat decodes a declared encoding that expat lacks through Python's codecs, and only a
        # single-byte one: an unknown name raises LookupError, a multi-byte one ValueError.
        raise ConfigError(
            f"the encoding of the XML declaration cannot be read ({error}); expected UTF-8, UTF-16, "
            "US-ASCII, ISO-8859-1 or another single-byte encoding",
            Location(file, parser.CurrentLineNumber or 1),
        ) from None
    return roots[0]
