"""CML, the Cool Muscle Language: syntax tree, parser and canonical formatter.

* :mod:`coolmuscle.cml.ast` - the tree (contract between parser, formatter, executor);
* :func:`parse` - one physical line of text -> ``list[Line]``, or
  :class:`~coolmuscle.errors.CmlSyntaxError` with the column;
* :func:`format_line`, :func:`format_statement`, :func:`format_expr` - canonical
  CML text as the motor prints it (bank readback, cml-users-guide.txt 6.6).
"""

from __future__ import annotations

from coolmuscle.cml.ast import Expr, Line, Statement
from coolmuscle.cml.formatter import format_expr, format_line, format_statement
from coolmuscle.cml.parser import parse

__all__ = ["parse", "format_line", "format_statement", "format_expr",
           "Line", "Statement", "Expr"]
