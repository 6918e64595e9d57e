"""TOML text of scene data, for tests that write scene files (the standard library reads TOML, writes none)."""
import math

from fabricfem import cli


def _value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float) and not math.isfinite(v):
        return "nan" if math.isnan(v) else ("inf" if v > 0 else "-inf")
    if isinstance(v, (int, float)):
        return repr(v)
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(v, list):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{" + ", ".join(f"{k} = {_value(x)}" for k, x in v.items()) + "}"
    raise TypeError(v)


def dumps(data: dict) -> str:
    """TOML text of a scene's data (tables, arrays of tables, one level of nested arrays of tables)."""
    lines = []
    for section, content in data.items():
        tables = content if isinstance(content, list) else [content]
        for table in tables:
            lines.append(f"[[{section}]]" if isinstance(content, list) else f"[{section}]")
            nested = {k: v for k, v in table.items() if isinstance(v, list) and v and isinstance(v[0], dict)}
            lines += [f"{k} = {_value(v)}" for k, v in table.items() if k not in nested]
            for key, items in nested.items():
                for item in items:
                    lines.append(f"[[{section}.{key}]]")
                    lines += [f"{k} = {_value(v)}" for k, v in item.items()]
    return "\n".join(lines) + "\n"


def refused_in_one_line(path, data: dict, key: str, capsys) -> str:
    """Write `data` to `path`, run `fabricfem run` on it: asserts exit 2 and one line on stderr naming `key`
    (no traceback); returns the line."""
    path.write_text(dumps(data))
    code = cli.main(["run", str(path)])
    lines = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    assert code == 2 and len(lines) == 1, lines
    assert key in lines[0] and "Traceback" not in lines[0], lines[0]
    return lines[0]
