#!/usr/bin/env python3
"""Reports the source files and functions that outgrow issue 16's structure rule.

The rule: no source file over ~500 lines and no function over ~80 lines unless its comment
says why. This script lists, for the .cc and .h files under core/ service/ clients/ idl/ tests/
(build folders and hidden folders skipped):
  - files over --max-file-lines lines (default 500), with their line count;
  - functions whose body spans over --max-function-lines lines (default 80), each as
    path:line (the first line of its declaration), its name and the lines from its opening
    brace to its closing brace. A function whose comment block right above it contains the
    word "long" (e.g. "// Long because ...") is listed as explained instead of as a finding.

Functions are found by a brace-matching heuristic, not a C++ parser: comments, string and
character literals and preprocessor lines are blanked out; a "{" at namespace or class scope
whose preceding text looks like a function header (a parameter list, then qualifiers, a
trailing return type or a constructor's initializer list) opens a function body, counted to
its matching "}". Namespaces, classes, structs and unions are descended into; enums,
initializers (anything after "=", brace-initialized variables) and every brace inside a
function body (lambdas, blocks) are not reported on their own.

It is a report, not a gate: it exits 0 whatever it finds.
"""

import argparse
import os
import re
import sys

SOURCE_FOLDERS = ("core", "service", "clients", "idl", "tests")
SOURCE_SUFFIXES = (".cc", ".h")


def is_skipped_folder(name):
    """Build trees (build, build-asan, cmake-build-debug, _deps) and hidden folders."""
    return (name.startswith(".") or name.startswith("build") or name.startswith("cmake-build")
            or name == "_deps")


def source_files(root):
    for folder in SOURCE_FOLDERS:
        top = os.path.join(root, folder)
        for directory, subfolders, files in os.walk(top):
            subfolders[:] = sorted(s for s in subfolders if not is_skipped_folder(s))
            for name in sorted(files):
                if name.endswith(SOURCE_SUFFIXES):
                    yield os.path.join(directory, name)


def _is_digit_separator(text, i):
    """A ' inside a number (C++14 1'000'000) rather than a character literal."""
    j = i - 1
    while j >= 0 and (text[j].isalnum() or text[j] in "_'."):
        j -= 1
    return j + 1 < i and text[j + 1].isdigit()


def blank_out(text):
    """The text with comments, literals and preprocessor lines replaced by spaces; newlines
    are kept so that offsets map to the same lines."""
    out = []
    i, n = 0, len(text)
    at_line_start = True
    while i < n:
        c = text[i]
        if at_line_start and c == "#":  # a preprocessor line, with its continuations
            while i < n and text[i] != "\n":
                if text[i] == "\\" and i + 1 < n and text[i + 1] == "\n":
                    out.append(" \n")
                    i += 2
                    continue
                out.append(" ")
                i += 1
            continue
        if c == "\n":
            out.append(c)
            at_line_start = True
            i += 1
            continue
        if not c.isspace():
            at_line_start = False
        if text.startswith("//", i):
            while i < n and text[i] != "\n":
                out.append(" ")
                i += 1
        elif text.startswith("/*", i):
            end = text.find("*/", i + 2)
            end = n if end < 0 else end + 2
            out.append(re.sub(r"[^\n]", " ", text[i:end]))
            i = end
        elif c == "R" and text.startswith('"', i + 1) and not (i and (text[i - 1].isalnum()
                                                                     or text[i - 1] == "_")):
            match = re.match(r'R"([^()\\\s]{0,16})\(', text[i:])
            if not match:
                out.append(c)
                i += 1
                continue
            close = ")" + match.group(1) + '"'
            end = text.find(close, i + match.end())
            end = n if end < 0 else end + len(close)
            out.append('"' + re.sub(r"[^\n]", " ", text[i + 1:end - 1]) + '"')
            i = end
        elif c == '"' or (c == "'" and not _is_digit_separator(text, i)):
            j = i + 1
            while j < n and text[j] != c and text[j] != "\n":
                j += 2 if text[j] == "\\" else 1
            out.append(c + " " * (min(j, n) - i - 1) + (c if j < n and text[j] == c else ""))
            i = j + 1 if j < n and text[j] == c else j
        else:
            out.append(c)
            i += 1
    return "".join(out)


def _top_level(text, opening, closing):
    """The text with every balanced (opening ... closing) group's content removed."""
    out, depth = [], 0
    for c in text:
        if c == opening:
            if depth == 0:
                out.append(c)
            depth += 1
        elif c == closing and depth > 0:
            depth -= 1
            if depth == 0:
                out.append(c)
        elif depth == 0:
            out.append(c)
    return "".join(out)


def _strip_templates(header):
    """Removes template<...> prefixes (balanced angle brackets)."""
    while True:
        match = re.search(r"\btemplate\s*<", header)
        if not match:
            return header
        depth, j = 0, match.end() - 1
        while j < len(header):
            if header[j] == "<":
                depth += 1
            elif header[j] == ">":
                depth -= 1
                if depth == 0:
                    break
            j += 1
        header = header[:match.start()] + " " + header[j + 1:]


QUALIFIERS = re.compile(
    r"^\s*(?:(?:const|volatile|noexcept|override|final|mutable|try|&&|&)\s*)*(?:->.*)?$", re.S)
CONSTRUCTOR_INITIALIZERS = re.compile(r"\)\s*(?:noexcept\s*)?:(?!:)")


def classify(header):
    """What a '{' at namespace or class scope opens, from the text before it."""
    header = re.sub(r"\[\[.*?\]\]", " ", header, flags=re.S)
    header = re.sub(r"^\s*(?:(?:public|private|protected)\s*:\s*)+", "", header)
    header = _strip_templates(header)
    flat = _top_level(header, "(", ")")
    if re.search(r"\bnamespace\b", flat) or re.search(r'\bextern\s*"', flat):
        return "scope"
    if re.search(r"\benum\b", flat):
        return "other"
    without_operators = re.sub(r"\boperator\s*[^\s(]*", " ", flat)
    if "=" in without_operators:
        return "other"
    last_paren = flat.rfind(")")
    if last_paren >= 0 and QUALIFIERS.match(flat[last_paren + 1:]):
        return "function"
    # A constructor's body after its initializer list, which may end in a member's "b_{x}"
    # (a brace after a member's name, "a_{", is that member's initializer instead).
    if CONSTRUCTOR_INITIALIZERS.search(flat) and flat.rstrip().endswith("}"):
        return "function"
    if re.search(r"\b(?:class|struct|union)\b", flat):
        return "scope"
    return "other"


def function_name(header):
    header = " ".join(header.split())
    match = re.search(r"\b(TEST|TEST_F|TEST_P|TYPED_TEST|TYPED_TEST_P)\s*\(([^)]*)\)", header)
    if match:
        return "%s(%s)" % (match.group(1), " ".join(match.group(2).split()))
    match = re.search(r"((?:[\w~]+\s*::\s*)*(?:operator\s*\(\s*\)|operator\s*[^\s(]+|~?\w+))\s*\(",
                      header)
    return match.group(1).replace(" ", "") if match else header[:60]


def class_name(header):
    """The name a class, struct or union header declares ("" for a namespace or an anonymous
    class)."""
    match = re.search(r"\b(?:class|struct|union)\s+(?:\[\[.*?\]\]\s*)?(\w+)",
                      _top_level(_strip_templates(header), "(", ")"))
    return match.group(1) if match and not re.search(r"\bnamespace\b", header) else ""


def find_functions(code):
    """(header start offset, open offset, close offset, header text, enclosing classes) of each
    function body at namespace or class scope."""
    functions = []
    stack = []  # kinds of the open braces: "scope", "function", "block", "other"
    header_start = 0
    paren_depth = 0
    for i, c in enumerate(code):
        inside_function = any(kind in ("function", "block", "other") for kind in stack)
        if c == "(":
            paren_depth += 1
        elif c == ")":
            paren_depth = max(0, paren_depth - 1)
        elif c == "{":
            if inside_function:
                stack.append(("block" if stack[-1][0] in ("function", "block") else "other", i))
                continue
            if paren_depth > 0:  # a lambda in a constructor's initializer list, say
                stack.append(("other", i))
                continue
            header = code[header_start:i]
            kind = classify(header)
            stack.append((kind, i, header_start, header))
            if kind != "other":
                header_start = i + 1
        elif c == "}":
            if not stack:
                continue
            entry = stack.pop()
            if entry[0] == "function":
                classes = [class_name(e[3]) for e in stack if e[0] == "scope"]
                functions.append((entry[2], entry[1], i, entry[3], [c for c in classes if c]))
            # After a function or a scope the next header starts; after an initializer at
            # namespace or class scope (a member's "a_{1}" in a constructor's initializer
            # list) the header goes on, up to the ";" or "{" that ends it.
            if entry[0] in ("function", "scope"):
                header_start = i + 1
        elif c == ";" and not inside_function and paren_depth == 0:
            header_start = i + 1
    return functions


def comment_above(lines, line_index):
    """The comment lines right above lines[line_index] (0-based), nearest last."""
    block = []
    j = line_index - 1
    in_block_comment = False
    while j >= 0:
        stripped = lines[j].strip()
        if in_block_comment:
            block.append(stripped)
            if "/*" in stripped:
                in_block_comment = False
            j -= 1
            continue
        if stripped.startswith("//"):
            block.append(stripped)
        elif stripped.endswith("*/"):
            block.append(stripped)
            in_block_comment = "/*" not in stripped
        else:
            break
        j -= 1
    return list(reversed(block))


def line_of(newline_offsets, offset):
    """1-based line number of a character offset."""
    lo, hi = 0, len(newline_offsets)
    while lo < hi:
        mid = (lo + hi) // 2
        if newline_offsets[mid] < offset:
            lo = mid + 1
        else:
            hi = mid
    return lo + 1


def check_file(path, max_function_lines):
    with open(path, encoding="utf-8", errors="replace") as f:
        text = f.read()
    lines = text.split("\n")
    line_count = text.count("\n") + (0 if text.endswith("\n") or not text else 1)
    code = blank_out(text)
    newlines = [i for i, c in enumerate(code) if c == "\n"]
    long_functions = []
    for header_start, open_offset, close_offset, header, classes in find_functions(code):
        first = header_start + (len(header) - len(header.lstrip()))
        start_line = line_of(newlines, first)
        body_lines = line_of(newlines, close_offset) - line_of(newlines, open_offset) + 1
        if body_lines <= max_function_lines:
            continue
        comment = " ".join(comment_above(lines, start_line - 1))
        explained = re.search(r"\blong\b", comment, re.I) is not None
        name = "::".join(classes + [function_name(header)])
        long_functions.append((start_line, name, body_lines, explained))
    return line_count, long_functions


def main():
    parser = argparse.ArgumentParser(
        description=__doc__.split("\n\n")[0],
        epilog="\n\n".join(__doc__.split("\n\n")[1:]),
        formatter_class=argparse.RawDescriptionHelpFormatter)
    default_root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    parser.add_argument("--root", default=default_root,
                        help="the repository root (default: the folder above scripts/, %(default)s)")
    parser.add_argument("--max-file-lines", type=int, default=500,
                        help="files longer than this are listed (default %(default)s)")
    parser.add_argument("--max-function-lines", type=int, default=80,
                        help="function bodies longer than this are listed (default %(default)s)")
    try:
        args = parser.parse_args()
    except SystemExit:  # --help, or a usage error (argparse printed it): still a report's 0
        return 0

    root = os.path.abspath(args.root)
    big_files, findings, explained = [], [], []
    files = 0
    for path in source_files(root):
        files += 1
        relative = os.path.relpath(path, root)
        line_count, long_functions = check_file(path, args.max_function_lines)
        if line_count > args.max_file_lines:
            big_files.append((relative, line_count))
        for start_line, name, body_lines, is_explained in long_functions:
            row = "%s:%d  %s  %d lines" % (relative, start_line, name, body_lines)
            (explained if is_explained else findings).append(row)

    print("structure check of %s: %d source files (.cc, .h under %s)" %
          (root, files, " ".join(f + "/" for f in SOURCE_FOLDERS)))
    print("\nfiles over %d lines: %d" % (args.max_file_lines, len(big_files)))
    for relative, line_count in big_files:
        print("  %s:1  %d lines" % (relative, line_count))
    print("\nfunctions over %d lines: %d" % (args.max_function_lines, len(findings)))
    for row in findings:
        print("  " + row)
    print("\nfunctions over %d lines whose comment says why (\"long\"): %d" %
          (args.max_function_lines, len(explained)))
    for row in explained:
        print("  " + row)
    return 0


if __name__ == "__main__":
    sys.exit(main())
