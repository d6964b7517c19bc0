"""A ROS-free core library links no ROS library (DESIGN.md section 2).

Checks every installed core library -- each lib*_core.so (adroit_core's libadroit_core.so
among them) and adroit_description's libadroit_description.so -- under the install tree
($ADROIT_INSTALL_BASE, default install/ beside scripts/): neither its ELF NEEDED entries
(readelf -d, binutils) nor its transitive dependencies (ldd) may be a ROS library, nor may
its link command in the build tree ($ADROIT_BUILD_BASE, default build/): Debian's toolchain
links with --as-needed, which drops a linked but unused ROS library from NEEDED, so the ELF
file alone would not show a CMake target that links roscpp (and whose exported link
interface hands roscpp to every user). One test case per library, so the result names it;
the failure message names the dependency.

A dependency is a ROS library when its name is one of ROS's C++ libraries (roscpp,
rosconsole*, roscpp_serialization, rostime, cpp_common, xmlrpcpp, tf2_ros, ... and the
workspace's own adroit_ros), or when the Debian package that installed it was built from a
ROS source package (source name ros-*, as every ROS package of Debian is). The detector
itself is tested on hand-made libraries compiled here with g++.
"""
import glob
import os
import re
import subprocess

import pytest

HERE = os.path.dirname(os.path.abspath(__file__))
INSTALL_BASE = os.environ.get("ADROIT_INSTALL_BASE", os.path.join(HERE, "..", "install"))
BUILD_BASE = os.environ.get("ADROIT_BUILD_BASE", os.path.join(HERE, "..", "build"))

# Named ROS libraries, also found when not installed from Debian (e.g. a workspace build).
ROS_NAME = re.compile(
    r"^lib(roscpp|roscpp_serialization|rosconsole\w*|rostime|cpp_common|xmlrpcpp|roslib|rospack|"
    r"rosbag\w*|roslz4|tf2_ros|tf2|tf|nodeletlib|bondcpp|class_loader|pluginlib|message_filters|"
    r"actionlib|topic_tools|image_transport|urdf|kdl_parser|adroit_ros)\.so(\.|$)")
# Libraries that are core libraries by name besides lib*_core.so.
EXTRA_CORE = ("libadroit_description.so", "libadroit_driver_can.so", "libadroit_can_robot.so",
              "libadroit_hardware_emulator.so", "libadroit_characterisation.so")


def core_libraries(install_base):
    """Installed core libraries, isolated (install/<pkg>/lib) or merged (install/lib) layout."""
    found = []
    for lib_dir in sorted(glob.glob(os.path.join(install_base, "*", "lib")) + [os.path.join(install_base, "lib")]):
        for path in sorted(glob.glob(os.path.join(lib_dir, "lib*.so"))):
            name = os.path.basename(path)
            if name.endswith("_core.so") or name in EXTRA_CORE:
                found.append(path)
    return found


def needed(path):
    """The ELF NEEDED entries of a shared object (readelf -d)."""
    out = subprocess.run(["readelf", "-d", path], check=True, capture_output=True, text=True).stdout
    return re.findall(r"\(NEEDED\)\s+Shared library: \[([^\]]+)\]", out)


def transitive(path, library_path):
    """{soname: resolved path or None} of everything the dynamic loader would load (ldd)."""
    env = dict(os.environ, LD_LIBRARY_PATH=":".join(library_path + [os.environ.get("LD_LIBRARY_PATH", "")]))
    out = subprocess.run(["ldd", path], check=True, capture_output=True, text=True, env=env).stdout
    deps = {}
    for line in out.splitlines():
        m = re.match(r"\s*(\S+) => (not found|(\S+) \(0x[0-9a-f]+\))", line)
        if m:
            deps[m.group(1)] = m.group(3)
    return deps


def ros_debian_files(paths):
    """The subset of paths installed by a Debian package built from a ROS source (ros-*)."""
    if not paths or not os.path.exists("/usr/bin/dpkg-query"):
        return set()
    # With merged /usr, ldd may name /lib/x/libfoo.so.1 where dpkg knows /usr/lib/x/... or the
    # versioned file the symlink points to: ask for every spelling.
    spellings = {}
    for p in paths:
        for s in {p, os.path.realpath(p), "/usr" + p if p.startswith("/lib") else p,
                  p[4:] if p.startswith("/usr/lib") else p}:
            spellings.setdefault(s, set()).add(p)
    out = subprocess.run(["dpkg-query", "-S"] + sorted(spellings), capture_output=True, text=True).stdout
    owner = {}  # path -> Debian package
    for line in out.splitlines():
        pkg, _, file = line.partition(": ")
        for p in spellings.get(file.strip(), ()):
            owner[p] = pkg.split(",")[0].strip()
    if not owner:
        return set()
    fmt = "${Package}:${Architecture} ${source:Package}\n"
    out = subprocess.run(["dpkg-query", "-W", "-f", fmt] + sorted(set(owner.values())),
                         capture_output=True, text=True).stdout
    ros_packages = set()
    for line in out.splitlines():
        pkg, _, source = line.partition(" ")
        if source.startswith("ros-"):
            ros_packages.update({pkg, pkg.split(":")[0]})
    return {p for p, pkg in owner.items() if pkg in ros_packages}


def ros_dependencies(path, library_path):
    """['libroscpp.so.4d (NEEDED)', 'librostime.so.1d (transitive)', ...] of one library."""
    direct = needed(path)
    deps = transitive(path, library_path)
    from_ros_packages = ros_debian_files([p for p in deps.values() if p])
    offending = []
    for name in sorted(set(direct) | set(deps)):
        resolved = deps.get(name)
        if ROS_NAME.match(name) or (resolved and resolved in from_ros_packages):
            where = "NEEDED" if name in direct else "transitive"
            offending.append(f"{name} ({where}{', ' + resolved if resolved else ''})")
    return offending


def link_command(library, build_base):
    """CMake's link command of an installed install/<pkg>/lib/lib<target>.so, or None."""
    pkg = os.path.basename(os.path.dirname(os.path.dirname(library)))
    target = os.path.basename(library)[len("lib"):-len(".so")]
    path = os.path.join(build_base, pkg, "CMakeFiles", f"{target}.dir", "link.txt")
    return path if os.path.exists(path) else None


def ros_link_inputs(link_txt):
    """['libroscpp.so', ...]: the ROS libraries a link command names (-lfoo or a path)."""
    with open(link_txt) as f:
        tokens = f.read().split()
    libs = {}  # basename -> path or None
    for t in tokens:
        if t.startswith("-l") and len(t) > 2:
            libs.setdefault(f"lib{t[2:]}.so", None)
        elif re.search(r"\.so(\.[0-9a-z.]*)?$", t) and not t.startswith("-"):
            libs[os.path.basename(t)] = t if os.path.isabs(t) else None
    from_ros_packages = ros_debian_files([p for p in libs.values() if p])
    return sorted(n for n, p in libs.items() if ROS_NAME.match(n) or (p and p in from_ros_packages))


def library_path_of(install_base):
    return sorted(glob.glob(os.path.join(install_base, "*", "lib"))) + [os.path.join(install_base, "lib")]


# ----------------------------------------------------------------------------- the check

INSTALLED = core_libraries(INSTALL_BASE)


@pytest.mark.parametrize("library", INSTALLED or ["<none>"],
                         ids=[os.path.basename(p) for p in INSTALLED] or ["no_core_library"])
def test_core_library_links_no_ros_library(library):
    assert INSTALLED, f"no core library (lib*_core.so, libadroit_description.so) under {INSTALL_BASE}"
    name = os.path.basename(library)
    offending = ros_dependencies(library, library_path_of(INSTALL_BASE))
    assert not offending, f"{name} ({library}) links ROS libraries: {', '.join(offending)}"
    link_txt = link_command(library, BUILD_BASE)
    named = ros_link_inputs(link_txt) if link_txt else []
    assert not named, (f"{name}: its link command ({link_txt}) names ROS libraries: {', '.join(named)} "
                       "(--as-needed dropped them from NEEDED, but the target links them)")


def test_the_main_core_libraries_are_checked():
    names = {os.path.basename(p) for p in INSTALLED}
    for name in ("libadroit_core.so", "libadroit_description.so", "libadroit_pneumatics_core.so",
                 "libadroit_learning_core.so"):
        assert name in names, f"{name} not found under {INSTALL_BASE}"


# ----------------------------------------------------------------------------- the detector

def compile_so(directory, name, source, *link):
    path = os.path.join(directory, f"lib{name}.so")
    src = os.path.join(directory, f"{name}.cpp")
    with open(src, "w") as f:
        f.write(source)
    # --no-as-needed: keep the NEEDED entry although nothing is called through it.
    subprocess.run(["g++", "-shared", "-fPIC", "-o", path, src, f"-L{directory}", "-Wl,--no-as-needed",
                    *link, f"-Wl,-rpath,{directory}"], check=True)
    return path


def test_detector_flags_exactly_the_libraries_that_link_ros(tmp_path):
    """A hand-made install tree: a fake libroscpp, a core library linking it directly, one
    linking it through a ROS-free helper, one linking only the helper's clean sibling, one
    clean, and a non-core library linking roscpp (not checked)."""
    ros = str(tmp_path / "ros" / "lib")
    os.makedirs(ros)
    compile_so(ros, "roscpp", "int ros_init() { return 1; }\n")
    lib = str(tmp_path / "install" / "pkg" / "lib")
    os.makedirs(lib)
    compile_so(lib, "helper", "int helper() { return 2; }\n", f"-L{ros}", "-lroscpp", f"-Wl,-rpath,{ros}")
    compile_so(lib, "clean_helper", "int clean_helper() { return 3; }\n")
    compile_so(lib, "direct_core", "int direct() { return 4; }\n", f"-L{ros}", "-lroscpp", f"-Wl,-rpath,{ros}")
    compile_so(lib, "indirect_core", "int indirect() { return 5; }\n", "-lhelper")
    compile_so(lib, "sibling_core", "int sibling() { return 6; }\n", "-lclean_helper")
    compile_so(lib, "clean_core", "int clean() { return 7; }\n")
    compile_so(lib, "pkg_nodes", "int nodes() { return 8; }\n", f"-L{ros}", "-lroscpp", f"-Wl,-rpath,{ros}")

    install = str(tmp_path / "install")
    found = core_libraries(install)
    assert [os.path.basename(p) for p in found] == [
        "libclean_core.so", "libdirect_core.so", "libindirect_core.so", "libsibling_core.so"]
    verdict = {os.path.basename(p): ros_dependencies(p, library_path_of(install)) for p in found}
    assert verdict["libclean_core.so"] == []
    assert verdict["libsibling_core.so"] == []
    assert verdict["libdirect_core.so"] == [f"libroscpp.so (NEEDED, {ros}/libroscpp.so)"]
    assert verdict["libindirect_core.so"] == [f"libroscpp.so (transitive, {ros}/libroscpp.so)"]


def test_detector_knows_the_debian_ros_libraries():
    for name in ("libroscpp.so.4d", "librosconsole.so.3d", "libroscpp_serialization.so.0d",
                 "librostime.so.1d", "libtf2_ros.so.1d", "libxmlrpcpp.so.3d", "libcpp_common.so.0d"):
        assert ROS_NAME.match(name), name
    for name in ("libmujoco.so.2.2.2", "libyaml-cpp.so.0.7", "libstdc++.so.6", "libadroit_core.so",
                 "librosx.so"):
        assert not ROS_NAME.match(name), name


def test_debian_ros_packages_are_recognised_by_their_source():
    """The dpkg layer: a Debian ROS library is flagged whatever its name, others are not."""
    ros = sorted(glob.glob("/usr/lib/*/libroscpp.so.*") + glob.glob("/usr/lib/*/librandom_numbers.so.*"))
    other = sorted(glob.glob("/usr/lib/*/libmujoco.so.*") + glob.glob("/usr/lib/*/libyaml-cpp.so.*"))
    if not ros or not other:
        pytest.skip("no Debian ROS library or no other library installed here")
    flagged = ros_debian_files(ros + other)
    assert flagged == set(ros)


def test_link_command_layer_finds_ros_libraries_dropped_by_as_needed(tmp_path):
    """A hand-made build tree: one core target's link command names roscpp (by path) and
    tf2_ros (-l), the other only ROS-free libraries."""
    install_lib = tmp_path / "install" / "pkg" / "lib"
    install_lib.mkdir(parents=True)
    build = tmp_path / "build"
    commands = {
        "dirty_core": "/usr/bin/c++ -fPIC -shared -Wl,-soname,libdirty_core.so -o libdirty_core.so a.o "
                      "/opt/x/lib/libadroit_core.so /usr/lib/x86_64-linux-gnu/libroscpp.so.4d -ltf2_ros -lpthread",
        "clean_core": "/usr/bin/c++ -fPIC -shared -o libclean_core.so a.o /opt/x/lib/libadroit_core.so "
                      "/usr/lib/x86_64-linux-gnu/libmujoco.so.2.2.2 -lyaml-cpp -Wl,-rpath,/opt/x/lib",
    }
    for target, command in commands.items():
        d = build / "pkg" / "CMakeFiles" / f"{target}.dir"
        d.mkdir(parents=True)
        (d / "link.txt").write_text(command + "\n")
    dirty = link_command(str(install_lib / "libdirty_core.so"), str(build))
    clean = link_command(str(install_lib / "libclean_core.so"), str(build))
    assert dirty and clean
    assert ros_link_inputs(dirty) == ["libroscpp.so.4d", "libtf2_ros.so"]
    assert ros_link_inputs(clean) == []
    assert link_command(str(install_lib / "libother_core.so"), str(build)) is None
