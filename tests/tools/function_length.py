#!/usr/bin/env python3
"""Lists C++ function bodies longer than a limit, as CTest's CoreFunctionLength entry runs it:

    function_length.py MAX_LINES FOLDER...
    function_length.py --self-test


Exit 0 when every function of every .cpp and .h under the folders has at most MAX_LINES lines
(from the line of its opening brace to that of its closing one), 1 listing file:line and length
of each one over it. A function is a brace block opened outside any function whose text since
the last ';', '{' or '}' holds a ')' and does not start a namespace, class, struct, enum or union
(lambdas and local classes count towards the function around them). Comments, string and
character literals are blanked first, so braces in them do not count.
"""
import os
import re
import sys

SCOPE = re.compile(r"\b(namespace|class|struct|enum|union)\b[^()]*$")


def digit_separator(text, i):
    """True when the quote at i separates digits (10'000), not opens a character literal (L'x')."""
    start = i
    while start > 0 and (text[start - 1].isalnum() or text[start - 1] == "_"):
        start -= 1
    return start < i and text[start].isdigit()


def blank_literals(text):
    """The text with comments, strings and character literals replaced by spaces (newlines kept)."""
    out, i, n = [], 0, len(text)
    while i < n:
        c = text[i]
        if text.startswith("//", i):
            j = text.find("\n", i)
            j = n if j < 0 else j
            out.append(" " * (j - i))
            i = j
        elif text.startswith("/*", i):
            j = text.find("*/", i + 2)
            j = n if j < 0 else j + 2
            out.append(re.sub(r"[^\n]", " ", text[i:j]))
            i = j
        elif c == '"' and text[max(0, i - 1)] == "R" and (i < 2 or not (text[i - 2].isalnum() or text[i - 2] == "_")):
            m = re.match(r'"([^(\s]*)\(', text[i:])
            end = text.find(")" + (m.group(1) if m else "") + '"', i)
            j = n if end < 0 else end + len(m.group(1) if m else "") + 2
            out.append(re.sub(r"[^\n]", " ", text[i:j]))
            i = j
        elif c == "'" and digit_separator(text, i):
            out.append(c)
            i += 1
        elif c in "\"'":
            j = i + 1
            while j < n and text[j] != c and text[j] != "\n":
                j += 2 if text[j] == "\\" else 1
            j = min(j + 1, n)
            out.append(" " * (j - i))
            i = j
        else:
            out.append(c)
            i += 1
    return "".join(out)


def long_functions(path, max_lines):
    with open(path, encoding="utf-8", errors="replace") as f:
        text = blank_literals(f.read())
    found, stack, head, line = [], [], "", 1  # stack: (is_function, line of its brace)
    for c in text:
        in_function = any(is_fn for is_fn, _ in stack)
        if c == "{":
            is_fn = not in_function and ")" in head and not SCOPE.search(head.strip()) and not head.strip().endswith("=")
            stack.append((is_fn, line))
            head = ""
        elif c == "}":
            if stack:
                is_fn, start = stack.pop()
                if is_fn and line - start + 1 > max_lines:
                    found.append((start, line - start + 1))
            head = ""
        elif c == ";":
            if not in_function:
                head = ""
        elif not in_function:
            head += c
        if c == "\n":
            line += 1
    return found


SAMPLE = r"""namespace a {
struct S {
  int f() const {
    return 1;
  }
  int x = 0;
};
const char* braces = "{{{ } //";
/* void g() { */
int h(int v = 10'000) {
  auto l = [](int k) {
    return k + L'}';
  };
  // }
  return l(v) + R"x({)x"[0];
}
}  // namespace a
"""


def self_test():
    """Known answers on a sample: S::f (3 lines) and h (7 lines, its lambda inside), nothing else."""
    import tempfile
    with tempfile.TemporaryDirectory() as folder:
        path = os.path.join(folder, "sample.cpp")
        with open(path, "w") as f:
            f.write(SAMPLE)
        got = {n: long_functions(path, n) for n in (0, 3, 7)}
    expected = {0: [(3, 3), (10, 7)], 3: [(10, 7)], 7: []}
    if got != expected:
        print(f"self-test failed: {got}, expected {expected}", file=sys.stderr)
        return 1
    print("self-test: the sample's two functions measured 3 and 7 lines")
    return 0


def main(argv):
    if argv[1:] == ["--self-test"]:
        return self_test()
    if len(argv) < 3 or not argv[1].isdigit():
        print(__doc__.strip().splitlines()[2].strip(), file=sys.stderr)
        return 2
    max_lines, over = int(argv[1]), []
    for root in argv[2:]:
        if not os.path.isdir(root):
            print(f"function_length.py: no folder {root}", file=sys.stderr)
            return 2
        for folder, _, files in sorted(os.walk(root)):
            for name in sorted(files):
                if name.endswith((".cpp", ".h")):
                    path = os.path.join(folder, name)
                    over += [(path, start, n) for start, n in long_functions(path, max_lines)]
    for path, start, n in over:
        print(f"{path}:{start}: a function of {n} lines (at most {max_lines})")
    return 1 if over else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
