"""
Static checks of the firmware: its hardware boundary, its Python subset, the ESP32 stubs.

- only the hardware layer (flash.HARDWARE_FILES) imports machine or esp32;
- the portable modules keep to what MicroPython and CPython both run;
- every name the hardware layer takes from machine, esp32, micropython, time and select,
  and every method it calls on their objects, exists in the ESP32 stubs of MicroPython
  1.27 (micropython-esp32-stubs, pinned in requirements/);
- pyflakes, flake8 and pep257 as the packages' linters run them;
- the flash script's board_params.py is the robot config's, and the staged file list is
  the whole firmware.
"""

import ast
import importlib.metadata
import importlib.util
from pathlib import Path
import re

from mecanum_control import board_core
from mecanum_control.board_params import board_params
from mecanum_control.robot_config import load_robot_config
import pytest

FIRMWARE = Path(__file__).resolve().parents[1]


def load_flash():
    """Import firmware/flash.py (a script, not a package module)."""
    spec = importlib.util.spec_from_file_location('firmware_flash', FIRMWARE / 'flash.py')
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


FLASH = load_flash()
HARDWARE_MODULES = ('machine', 'esp32', 'network', 'bluetooth', 'esp')
#: Modules whose names the hardware layer uses, checked against the stubs.
STUBBED_MODULES = ('machine', 'esp32', 'micropython', 'time', 'select')
#: Methods the hardware layer calls on objects of stubbed classes.
METHODS_USED = {
    'PWM': ('duty_u16',), 'Pin': ('value',), 'Encoder': ('value',), 'ADC': ('read_uv',),
    'UART': ('read', 'write'), 'WDT': ('feed',),
    'I2C': ('readfrom_mem_into', 'readfrom_mem', 'writeto_mem'),
}


def parse(path: Path) -> ast.Module:
    """Return the syntax tree of a file."""
    return ast.parse(path.read_text(), str(path))


def imported_modules(tree: ast.Module):
    """Return the top-level module names a syntax tree imports."""
    names = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names.update(alias.name.split('.')[0] for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module:
            names.add(node.module.split('.')[0])
    return names


@pytest.mark.parametrize('board_path', sorted(FLASH.BOARD_FILES))
def test_only_the_hardware_layer_imports_machine(board_path):
    """machine/esp32 appear only in main.py and hardware_esp32.py."""
    hardware = imported_modules(parse(FLASH.BOARD_FILES[board_path])) & set(HARDWARE_MODULES)
    if board_path in FLASH.HARDWARE_FILES:
        assert hardware, f'{board_path} is listed as hardware but imports none'
    else:
        assert not hardware, f'{board_path} imports {hardware}: only the hardware layer may'


@pytest.mark.parametrize('board_path', sorted(set(FLASH.BOARD_FILES) - set(FLASH.HARDWARE_FILES)))
def test_portable_files_keep_to_the_micropython_subset(board_path):
    """No dataclasses, enum, typing, f-strings or annotations in what runs on the board."""
    tree = parse(FLASH.BOARD_FILES[board_path])
    assert not imported_modules(tree) & {'dataclasses', 'enum', 'typing', 'abc'}
    for node in ast.walk(tree):
        assert not isinstance(node, (ast.JoinedStr, ast.AnnAssign)), (
            f'{board_path}:{node.lineno}: f-string or annotation')
        if isinstance(node, ast.FunctionDef):
            assert node.returns is None and all(
                arg.annotation is None for arg in node.args.args), (
                f'{board_path}:{node.lineno}: annotated function')


def stub_tree(module: str) -> ast.Module:
    """Return the syntax tree of a module's ESP32 stub."""
    try:
        distribution = importlib.metadata.distribution('micropython-esp32-stubs')
    except importlib.metadata.PackageNotFoundError:
        pytest.skip('micropython-esp32-stubs is not installed (make setup installs it)')
    path = Path(distribution.locate_file(f'{module}.pyi'))
    if not path.exists():
        stdlib = importlib.metadata.distribution('micropython-stdlib-stubs')
        path = Path(stdlib.locate_file(f'stdlib/{module}.pyi'))
    return parse(path)


def defined_names(body) -> set:
    """Return the names a module or class body defines (defs, classes, assignments)."""
    names = set()
    for node in body:
        if isinstance(node, (ast.FunctionDef, ast.ClassDef)):
            names.add(node.name)
        elif isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
            names.add(node.target.id)
        elif isinstance(node, ast.Assign):
            names.update(t.id for t in node.targets if isinstance(t, ast.Name))
        elif isinstance(node, (ast.Import, ast.ImportFrom)):
            names.update((alias.asname or alias.name).split('.')[0] for alias in node.names)
    return names


def test_stubs_are_micropython_1_27():
    """The pinned stubs are those of MicroPython 1.27, the firmware's interpreter."""
    try:
        version = importlib.metadata.version('micropython-esp32-stubs')
    except importlib.metadata.PackageNotFoundError:
        pytest.skip('micropython-esp32-stubs is not installed (make setup installs it)')
    assert re.match(r'1\.27\.', version), version


@pytest.mark.parametrize('board_path', FLASH.HARDWARE_FILES)
def test_hardware_layer_uses_only_names_the_esp32_stubs_define(board_path):
    """Every machine/esp32/... name, attribute and method used exists for the ESP32."""
    tree = parse(FLASH.BOARD_FILES[board_path])
    stubs = {}
    classes = {}
    aliases = {}   # local name -> (module, attribute or None)
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.module in STUBBED_MODULES:
            for alias in node.names:
                aliases[alias.asname or alias.name] = (node.module, alias.name)
        elif isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name in STUBBED_MODULES:
                    aliases[alias.asname or alias.name] = (alias.name, None)
    for module in {module for module, _ in aliases.values()}:
        tree_of_stub = stub_tree(module)
        stubs[module] = defined_names(tree_of_stub.body)
        classes[module] = {node.name: defined_names(node.body) for node in tree_of_stub.body
                           if isinstance(node, ast.ClassDef)}
    missing = []
    for local, (module, name) in aliases.items():
        if name is not None and name not in stubs[module]:
            missing.append(f'{module}.{name}')
    for node in ast.walk(tree):
        if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) \
                and node.value.id in aliases:
            module, name = aliases[node.value.id]
            known = stubs[module] if name is None else classes[module].get(name, set())
            if node.attr not in known:
                missing.append(f'{module}.{name + "." if name else ""}{node.attr}')
    for class_name, methods in METHODS_USED.items():
        for method in methods:
            if class_name not in classes.get('machine', {}) or \
                    method not in classes['machine'][class_name]:
                missing.append(f'machine.{class_name}.{method}')
    assert not missing, f'not in the ESP32 stubs of MicroPython 1.27: {sorted(set(missing))}'


def test_methods_used_list_is_the_hardware_layers():
    """Every method METHODS_USED names is called in hardware_esp32.py or imu_drivers.py."""
    text = (FIRMWARE / 'hardware_esp32.py').read_text() + (FIRMWARE / 'imu_drivers.py').read_text()
    for methods in METHODS_USED.values():
        for method in methods:
            assert f'.{method}(' in text, method


def test_pyflakes_finds_nothing():
    """Run pyflakes on every firmware file (undefined names, unused imports)."""
    from pyflakes.api import checkPath
    from pyflakes.reporter import Reporter
    import io
    out = io.StringIO()
    files = sorted(FIRMWARE.glob('*.py')) + sorted(FIRMWARE.glob('test/*.py')) + sorted(
        FIRMWARE.glob('unix_port/*.py'))
    problems = sum(checkPath(str(path), Reporter(out, out)) for path in files)
    assert problems == 0, out.getvalue()


@pytest.mark.linter
@pytest.mark.flake8
def test_flake8():
    """ament_flake8 (the packages' configuration) on the firmware folder."""
    from ament_flake8.main import main_with_errors
    rc, errors = main_with_errors(argv=[str(FIRMWARE)])
    assert rc == 0, f'Found {len(errors)} code style errors / warnings:\n' + '\n'.join(errors)


@pytest.mark.linter
@pytest.mark.pep257
def test_pep257():
    """ament_pep257 on the firmware folder."""
    from ament_pep257.main import main
    assert main(argv=[str(FIRMWARE)]) == 0, 'Found code style errors / warnings'


def test_board_params_file_is_the_robot_configs(tmp_path):
    """flash.py's board_params.py holds board_params(robot config), every PARAM_NAMES."""
    config_path = FLASH.ROBOT_CONFIG
    namespace = {}
    exec(FLASH.params_source(config_path), namespace)  # noqa: S102 - our generated file
    params = namespace['PARAMS']
    assert params == board_params(load_robot_config(config_path))
    assert sorted(params) == sorted(board_core.PARAM_NAMES)


def test_flash_stages_every_firmware_file(capsys):
    """A dry run stages the whole firmware and names each file in the mpremote command."""
    assert FLASH.main(['--port', '/dev/ttyUSB0', '--dry-run']) == 0
    out = capsys.readouterr().out
    staged = Path(out.split('staged in ')[1].split(':')[0])
    for board_path in list(FLASH.BOARD_FILES) + [FLASH.PARAMS_FILE]:
        assert (staged / board_path).is_file(), board_path
        assert f':{board_path}' in out, board_path
    assert (staged / 'mecanum_control' / 'esp32_wire.py').read_text() == \
        (FLASH.PACKAGE / 'esp32_wire.py').read_text()
    on_board = {path.name for path in FIRMWARE.glob('*.py')} - {'flash.py'}
    assert on_board <= set(FLASH.BOARD_FILES), on_board - set(FLASH.BOARD_FILES)


#: Keywords the ESP32 port takes that the generic stubs lack: machine.I2C's timeout
#: (microseconds; ports/esp32/machine_i2c.c), the hardware layer's guard on a stuck bus.
ESP32_KEYWORDS_NOT_IN_STUBS = {'I2C': {'timeout'}}


def constructor_parameters(class_node: ast.ClassDef):
    """Return (names, takes **kwargs) of every __init__ overload of a class, merged."""
    names, open_ended = set(), False
    for node in class_node.body:
        if isinstance(node, ast.FunctionDef) and node.name == '__init__':
            args = node.args
            names |= {arg.arg for arg in args.posonlyargs + args.args + args.kwonlyargs}
            open_ended |= args.kwarg is not None
    return names, open_ended


def machine_keywords_used():
    """Return {class: keywords} the hardware layer passes to machine's constructors."""
    tree = parse(FIRMWARE / 'hardware_esp32.py')
    classes = {alias.asname or alias.name for node in tree.body
               if isinstance(node, ast.ImportFrom) and node.module == 'machine'
               for alias in node.names}
    used = {}
    for node in ast.walk(tree):
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) \
                and node.func.id in classes:
            used.setdefault(node.func.id, set()).update(
                keyword.arg for keyword in node.keywords)
    return used


def test_hardware_layer_keywords_exist_in_the_esp32_stubs():
    """Every keyword the hardware layer gives machine's constructors is in the stubs."""
    stubs = {node.name: node for node in stub_tree('machine').body
             if isinstance(node, ast.ClassDef)}
    missing = []
    for class_name, keywords in machine_keywords_used().items():
        names, open_ended = constructor_parameters(stubs[class_name])
        extra = ESP32_KEYWORDS_NOT_IN_STUBS.get(class_name, set())
        if not open_ended:
            missing += [f'{class_name}({keyword}=)' for keyword in sorted(keywords)
                        if keyword not in names | extra]
    assert not missing, f'not in the ESP32 stubs of MicroPython 1.27: {missing}'
    assert machine_keywords_used()['I2C'] >= {'timeout'}


def test_unix_stand_in_takes_the_stubs_keywords():
    """The unix board's stand-in machine: each constructor takes the stubs' keywords."""
    stubs = {node.name: node for node in stub_tree('machine').body
             if isinstance(node, ast.ClassDef)}
    stand_in = {node.name: node for node in parse(FIRMWARE / 'unix_port' / 'machine.py').body
                if isinstance(node, ast.ClassDef)}
    wrong = []
    for class_name, keywords in machine_keywords_used().items():
        names, open_ended = constructor_parameters(stand_in[class_name])
        stub_names, stub_open = constructor_parameters(stubs[class_name])
        for keyword in keywords:
            if keyword not in names and not open_ended:
                wrong.append(f'{class_name}({keyword}=) refused by the stand-in')
        # Keyword-only in the stubs: the same names in the stand-in (a keyword the
        # board takes must not be positional-only there, nor the reverse).
        for node in stubs[class_name].body:
            if isinstance(node, ast.FunctionDef) and node.name == '__init__':
                for arg in node.args.kwonlyargs:
                    if arg.arg not in names and not open_ended:
                        wrong.append(f'{class_name}: stub keyword {arg.arg} missing')
        assert stub_names or stub_open
    assert not wrong, wrong
