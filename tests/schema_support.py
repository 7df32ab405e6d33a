"""Validation of coolmuscle's CI output against the published schemas (tests/data/schemas).

* :func:`validate_sarif` - a SARIF log against the OASIS SARIF 2.1.0 JSON schema
  (jsonschema, draft 4 as the schema declares);
* :func:`validate_cobertura` - a coverage XML against Cobertura's coverage-04 DTD.  No DTD
  validator is among the test dependencies, so :class:`Dtd` reads the DTD's declarations
  (``<!ELEMENT name model>``, ``<!ATTLIST element attribute CDATA default>``) and checks
  what a validating parser checks for them: every element declared, its children in the
  order and number its content model allows (the model turned into a regular expression
  over the children's names), text only where ``#PCDATA`` is, every ``#REQUIRED``
  attribute present and no undeclared one.  The DTD's parameter entities, enumerated and
  ID attribute types are not used by coverage-04 and not read.
"""

from __future__ import annotations

import json
import re
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from functools import cache
from pathlib import Path
from typing import Any

import jsonschema

SCHEMAS = Path(__file__).resolve().parent / "data" / "schemas"
SARIF_SCHEMA = SCHEMAS / "sarif-schema-2.1.0.json"
COBERTURA_DTD = SCHEMAS / "cobertura-coverage-04.dtd"

_ELEMENT = re.compile(r"<!ELEMENT\s+([\w.-]+)\s+(EMPTY|ANY|\(.*?\)[*+?]?)\s*>", re.S)
_ATTLIST = re.compile(r"<!ATTLIST\s+([\w.-]+)\s+([\w.-]+)\s+CDATA\s+(#REQUIRED|#IMPLIED|"
                      r"\"[^\"]*\")\s*>")
_COMMENT = re.compile(r"<!--.*?-->", re.S)


@cache
def _sarif_validator() -> jsonschema.Draft4Validator:
    schema = json.loads(SARIF_SCHEMA.read_text(encoding="utf-8"))
    return jsonschema.Draft4Validator(schema, format_checker=jsonschema.Draft4Validator
                                      .FORMAT_CHECKER)


def validate_sarif(document: dict[str, Any]) -> None:
    """Raise ``jsonschema.ValidationError`` unless ``document`` is a valid SARIF 2.1.0 log."""
    _sarif_validator().validate(document)


class DtdError(AssertionError):
    """A document the DTD does not allow (the message says where)."""


@dataclass
class Dtd:
    """The element and attribute declarations of a DTD."""

    models: dict[str, str] = field(default_factory=dict)        # element -> model
    attributes: dict[str, dict[str, str]] = field(default_factory=dict)

    @classmethod
    def read(cls, path: Path) -> Dtd:
        text = _COMMENT.sub("", path.read_text(encoding="utf-8"))
        dtd = cls()
        for name, model in _ELEMENT.findall(text):
            dtd.models[name] = re.sub(r"\s+", "", model)
        for element, name, default in _ATTLIST.findall(text):
            dtd.attributes.setdefault(element, {})[name] = default
        if not dtd.models:
            raise ValueError(f"{path}: no element declarations")
        return dtd

    def children_pattern(self, element: str) -> re.Pattern[str] | None:
        """The children a model allows, as a regular expression over ``name,`` words
        (``None`` for ANY)."""
        model = self.models[element]
        if model == "ANY":
            return None
        if model == "EMPTY" or model == "(#PCDATA)":
            return re.compile("")
        if model.startswith("(#PCDATA"):                       # mixed: (#PCDATA|a|b)*
            names = model.strip("()*").split("|")[1:]
            return re.compile("(?:" + "|".join(f"{re.escape(n)}," for n in names) + ")*")
        parts = []
        for token in re.findall(r"[\w.-]+|[()|*+?,]", model):
            if token == ",":
                continue                                       # a sequence: one after another
            parts.append(f"(?:{re.escape(token)},)" if token[0].isalnum() else token)
        return re.compile("".join(parts))

    def validate(self, root: ET.Element) -> None:
        """Raise :class:`DtdError` at the first element the DTD does not allow."""
        self._element(root, root.tag)

    def _element(self, element: ET.Element, where: str) -> None:
        tag = element.tag
        if tag not in self.models:
            raise DtdError(f"{where}: element <{tag}> is not declared")
        model = self.models[tag]
        declared = self.attributes.get(tag, {})
        for name in element.attrib:
            if name not in declared:
                raise DtdError(f"{where}: attribute {name!r} is not declared for <{tag}>")
        for name, default in declared.items():
            if default == "#REQUIRED" and name not in element.attrib:
                raise DtdError(f"{where}: <{tag}> lacks the required attribute {name!r}")
        text = (element.text or "").strip() + "".join((c.tail or "").strip() for c in element)
        if text and "#PCDATA" not in model and model != "ANY":
            raise DtdError(f"{where}: <{tag}> holds text, its model is {model}")
        pattern = self.children_pattern(tag)
        names = "".join(f"{child.tag}," for child in element)
        if pattern is not None and not pattern.fullmatch(names):
            raise DtdError(f"{where}: the children of <{tag}> ({names.rstrip(',') or 'none'})"
                           f" do not match {model}")
        for index, child in enumerate(element):
            self._element(child, f"{where}/{child.tag}[{index}]")


@cache
def cobertura_dtd() -> Dtd:
    return Dtd.read(COBERTURA_DTD)


def validate_cobertura(path: Path) -> ET.Element:
    """Raise :class:`DtdError` unless ``path`` is a document coverage-04.dtd allows (its
    DOCTYPE naming that DTD); the root element."""
    text = path.read_text(encoding="utf-8")
    if "<!DOCTYPE coverage SYSTEM" not in text or "coverage-04.dtd" not in text:
        raise DtdError(f"{path}: no DOCTYPE naming coverage-04.dtd")
    root = ET.fromstring(text)
    cobertura_dtd().validate(root)
    return root
