"""The package's structural rules (docs/architecture.md), checked on the
source: each fails when a change breaks the rule it names."""

import ast
import subprocess
import sys
from pathlib import Path

import pytest

import sfanav

PKG = Path(sfanav.__file__).parent

# Stages in pipeline order: a module may import its own stage and the ones
# before it, never one after it. The private helpers (_checks, _progress,
# _plotting, _threads, _core) come first; sfanav.pipeline (the training
# recipe applied to a run) composes the stages up to odometry; the package root
# re-exports the stages; app and experiments sit on top.
ORDER = ["_private", "data", "features", "groundtruth", "sim", "loopclosure", "sfa", "localization", "landmarks", "odometry",
         "pipeline", "navigation", "_root", "experiments", "app"]
LIBRARY = {"_private", "data", "features", "groundtruth", "sim", "loopclosure", "sfa", "localization", "landmarks", "odometry",
           "pipeline", "navigation", "_root"}


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(PKG.parent).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def _stage(module: str) -> str:
    parts = module.split(".")
    if len(parts) == 1:
        return "_root"
    if parts[1].startswith("_"):
        return "app" if parts[1] == "__main__" else "_private"
    return parts[1]


MODULES = {_module_name(p): p for p in sorted(PKG.rglob("*.py"))}


def _type_checking_nodes(tree: ast.AST) -> set[int]:
    """ids of nodes under ``if TYPE_CHECKING:`` (annotation-only imports)."""
    skip: set[int] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            for sub in node.body:
                skip.update(id(n) for n in ast.walk(sub))
    return skip


def _imports(module: str, path: Path):
    """(imported module, imported name or None, line) of every import of an
    sfanav module, relative ones resolved; annotation-only ones left out."""
    tree = ast.parse(path.read_text())
    skip = _type_checking_nodes(tree)
    is_pkg = path.name == "__init__.py"
    for node in ast.walk(tree):
        if id(node) in skip:
            continue
        if isinstance(node, ast.Import):
            for a in node.names:
                if a.name.split(".")[0] == "sfanav":
                    yield a.name, None, node.lineno
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = module.split(".")
                if not is_pkg:
                    base = base[:-1]
                base = base[: len(base) - (node.level - 1)]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            if target.split(".")[0] != "sfanav":
                continue
            for a in node.names:
                sub = f"{target}.{a.name}"
                if sub in MODULES or sub == "sfanav._core":
                    yield sub, None, node.lineno
                else:
                    yield target, a.name, node.lineno


def test_import_sfanav_does_not_load_the_command_line_or_the_experiments():
    code = ("import sys, sfanav; bad = sorted(m for m in sys.modules if m.startswith(('sfanav.app', "
            "'sfanav.experiments'))); print(','.join(bad))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.strip()
    assert out == "", f"import sfanav loads {out}"


def test_stages_import_only_earlier_stages():
    bad = []
    for module, path in MODULES.items():
        here = _stage(module)
        for target, _, line in _imports(module, path):
            there = _stage(target)
            if ORDER.index(there) > ORDER.index(here):
                bad.append(f"{path.relative_to(PKG)}:{line} ({here}) imports {target} ({there})")
    assert not bad, "imports against the pipeline order:\n" + "\n".join(bad)


def test_the_library_never_imports_the_command_line_or_the_experiments():
    bad = [f"{path.relative_to(PKG)}:{line} imports {target}"
           for module, path in MODULES.items() if _stage(module) in LIBRARY
           for target, _, line in _imports(module, path) if _stage(target) in ("app", "experiments")]
    assert not bad, "\n".join(bad)


def test_the_simulator_imports_no_sfa():
    bad = [f"{path.relative_to(PKG)}:{line} imports {target}"
           for module, path in MODULES.items() if _stage(module) == "sim"
           for target, _, line in _imports(module, path) if _stage(target) not in ("sim", "data", "_private")]
    assert not bad, "\n".join(bad)


def test_no_module_imports_another_modules_private_names():
    bad = []
    for module, path in MODULES.items():
        for target, name, line in _imports(module, path):
            if name is not None and name.startswith("_") and not name.startswith("__") and target != module:
                bad.append(f"{path.relative_to(PKG)}:{line} imports {name} from {target}")
    assert not bad, "\n".join(bad)


def test_no_module_reaches_into_another_modules_private_attributes():
    """``alias._name`` where ``alias`` is an imported sfanav module."""
    bad = []
    for module, path in MODULES.items():
        tree = ast.parse(path.read_text())
        aliases = {}
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom) and node.level and node.module is None:
                for a in node.names:
                    aliases[a.asname or a.name] = a.name
            elif isinstance(node, ast.ImportFrom) and node.level:
                for a in node.names:
                    aliases.setdefault(a.asname or a.name, a.name)
            elif isinstance(node, ast.Import):
                for a in node.names:
                    if a.name.startswith("sfanav"):
                        aliases[(a.asname or a.name).split(".")[0]] = a.name
        for node in ast.walk(tree):
            if (isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) and node.value.id in aliases
                    and node.attr.startswith("_") and not node.attr.startswith("__") and node.value.id != "_core"):
                bad.append(f"{path.relative_to(PKG)}:{node.lineno} uses {node.value.id}.{node.attr}")
    assert not bad, "\n".join(bad)


@pytest.mark.parametrize("stage", ["data", "groundtruth", "sfa", "localization", "landmarks", "odometry", "navigation", "sim", "loopclosure"])
def test_each_stage_imports_on_its_own(stage):
    code = f"import sfanav.{stage}"
    subprocess.run([sys.executable, "-c", code], check=True)


@pytest.mark.parametrize("old", ["metric", "workflow", "network", "defaults"])
def test_the_flat_layouts_module_paths_are_gone(old):
    """Each name has one home: the flat layout's modules (sfanav.metric,
    sfanav.workflow, ...) neither import nor resolve as attributes."""
    import sfanav

    assert not hasattr(sfanav, old)
    with pytest.raises(ModuleNotFoundError):
        __import__(f"sfanav.{old}")


def test_modules_stay_readable_in_size():
    """No library module over 1100 lines (the target is about 800)."""
    big = {str(p.relative_to(PKG)): n for p in PKG.rglob("*.py") if (n := len(p.read_text().splitlines())) > 1100}
    assert not big, big
