// render_states: draws recorded states of a scene offscreen with MuJoCo's renderer, one PPM
// image per requested time, for the README's image strips (scripts compose them into a PNG).
//
//   render_states --model scene.xml --states states.csv --times 0,0.5,1 --out /tmp/frame
//                 [--width 480] [--height 360] [--lookat-site S_grasp] [--distance 0.5]
//                 [--azimuth 90] [--elevation -25]
//
// states.csv: a header `time,<column>,...` then one row per sample. A column is a 1-DOF joint
// name (hinge or slide) or `<free joint>:x|y|z|qw|qx|qy|qz`; joints without a column keep the
// model's home pose. Each frame shows the last sample at or before its time. Needs an OpenGL
// context: a hidden GLFW window (under Xvfb on a headless machine).
#include <GLFW/glfw3.h>
#include <mujoco/mujoco.h>

#include "adroit_core/bounded_file.h"

#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <iostream>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

namespace {

struct Options {
  std::string model, states, out;
  std::vector<double> times;
  int width = 480, height = 360;
  std::string lookat_site = "S_grasp";
  double distance = 0.5, azimuth = 90, elevation = -25;
};

std::vector<std::string> split(const std::string& text, char separator) {
  std::vector<std::string> parts;
  std::stringstream stream(text);
  std::string part;
  while (std::getline(stream, part, separator)) parts.push_back(part);
  return parts;
}

double number(const std::string& text, const std::string& what) {
  char* end = nullptr;
  const double value = std::strtod(text.c_str(), &end);
  if (text.empty() || *end != '\0') throw std::invalid_argument(what + ": not a number '" + text + "'");
  return value;
}

Options parse(int argc, char** argv) {
  Options o;
  for (int i = 1; i < argc; ++i) {
    const std::string flag = argv[i];
    if (i + 1 >= argc) throw std::invalid_argument(flag + " needs a value");
    const std::string value = argv[++i];
    if (flag == "--model") o.model = value;
    else if (flag == "--states") o.states = value;
    else if (flag == "--out") o.out = value;
    else if (flag == "--times") for (const auto& t : split(value, ',')) o.times.push_back(number(t, flag));
    else if (flag == "--width") o.width = static_cast<int>(number(value, flag));
    else if (flag == "--height") o.height = static_cast<int>(number(value, flag));
    else if (flag == "--lookat-site") o.lookat_site = value;
    else if (flag == "--distance") o.distance = number(value, flag);
    else if (flag == "--azimuth") o.azimuth = number(value, flag);
    else if (flag == "--elevation") o.elevation = number(value, flag);
    else throw std::invalid_argument("unknown option " + flag);
  }
  if (o.model.empty() || o.states.empty() || o.out.empty() || o.times.empty())
    throw std::invalid_argument("--model, --states, --times and --out are required");
  if (o.width < 16 || o.height < 16 || o.width > 4096 || o.height > 4096)
    throw std::invalid_argument("image size must be within 16..4096 pixels");
  return o;
}

// Column -> qpos address, resolved once against the model.
std::vector<int> resolveColumns(const mjModel* m, const std::vector<std::string>& header) {
  static const std::vector<std::string> free_fields = {"x", "y", "z", "qw", "qx", "qy", "qz"};
  std::vector<int> address;
  for (std::size_t c = 1; c < header.size(); ++c) {
    const auto parts = split(header[c], ':');
    const int joint = mj_name2id(m, mjOBJ_JOINT, parts[0].c_str());
    if (joint < 0) throw std::invalid_argument("states column '" + header[c] + "': no such joint in the model");
    const int adr = m->jnt_qposadr[joint];
    if (parts.size() == 1 && (m->jnt_type[joint] == mjJNT_HINGE || m->jnt_type[joint] == mjJNT_SLIDE)) {
      address.push_back(adr);
      continue;
    }
    int field = -1;
    for (std::size_t f = 0; parts.size() == 2 && f < free_fields.size(); ++f)
      if (parts[1] == free_fields[f]) field = static_cast<int>(f);
    if (m->jnt_type[joint] != mjJNT_FREE || field < 0)
      throw std::invalid_argument("states column '" + header[c] + "': use <1-DOF joint> or <free joint>:x|y|z|qw|qx|qy|qz");
    address.push_back(adr + field);
  }
  return address;
}

struct Sample {
  double time;
  std::vector<double> values;
};

std::vector<Sample> readStates(const std::string& path, std::vector<std::string>& header) {
  // A states file is a few MB (an hour at 500 Hz with 30 joints is ~500 MB of CSV).
  std::istringstream file(adroit::readBoundedFile(path, adroit::kGiB));
  std::string line;
  if (!std::getline(file, line)) throw std::invalid_argument(path + ": empty");
  header = split(line, ',');
  if (header.empty() || header[0] != "time") throw std::invalid_argument(path + ": the first column must be 'time'");
  std::vector<Sample> samples;
  for (int row = 2; std::getline(file, line); ++row) {
    if (line.empty()) continue;
    const auto cells = split(line, ',');
    if (cells.size() != header.size())
      throw std::invalid_argument(path + ":" + std::to_string(row) + ": " + std::to_string(cells.size()) +
                                  " values, header has " + std::to_string(header.size()));
    Sample s{number(cells[0], path + ":" + std::to_string(row)), {}};
    for (std::size_t c = 1; c < cells.size(); ++c) s.values.push_back(number(cells[c], path + ":" + std::to_string(row)));
    samples.push_back(std::move(s));
  }
  if (samples.empty()) throw std::invalid_argument(path + ": no samples");
  return samples;
}

void writePpm(const std::string& path, const std::vector<unsigned char>& rgb, int width, int height) {
  std::ofstream file(path, std::ios::binary);
  if (!file) throw std::runtime_error("cannot write " + path);
  file << "P6\n" << width << " " << height << "\n255\n";
  // OpenGL rows run bottom-up.
  for (int row = height - 1; row >= 0; --row)
    file.write(reinterpret_cast<const char*>(rgb.data() + 3 * width * row), 3 * width);
}

}  // namespace

int main(int argc, char** argv) {
  try {
    const Options o = parse(argc, argv);
    char error[1000] = "";
    mjModel* m = mj_loadXML(o.model.c_str(), nullptr, error, sizeof(error));
    if (!m) throw std::runtime_error("cannot load " + o.model + ": " + error);
    m->vis.global.offwidth = o.width;
    m->vis.global.offheight = o.height;
    mjData* d = mj_makeData(m);
    std::vector<std::string> header;
    const std::vector<Sample> samples = readStates(o.states, header);
    const std::vector<int> address = resolveColumns(m, header);

    if (!glfwInit()) throw std::runtime_error("no OpenGL: glfwInit failed (no display? run under xvfb-run)");
    glfwWindowHint(GLFW_VISIBLE, GLFW_FALSE);
    GLFWwindow* window = glfwCreateWindow(o.width, o.height, "render_states", nullptr, nullptr);
    if (!window) throw std::runtime_error("no OpenGL: cannot create a hidden GLFW window");
    glfwMakeContextCurrent(window);

    mjvScene scene;
    mjvCamera camera;
    mjvOption option;
    mjrContext context;
    mjv_defaultScene(&scene);
    mjv_defaultCamera(&camera);
    mjv_defaultOption(&option);
    option.flags[mjVIS_TENDON] = 0;  // 40 tendon lines hide the fingers at strip size
    mjr_defaultContext(&context);
    mjv_makeScene(m, &scene, 2000);
    mjr_makeContext(m, &context, mjFONTSCALE_100);
    mjr_setBuffer(mjFB_OFFSCREEN, &context);
    const int site = mj_name2id(m, mjOBJ_SITE, o.lookat_site.c_str());
    if (site < 0) throw std::invalid_argument("unknown --lookat-site " + o.lookat_site);

    std::vector<unsigned char> rgb(3 * o.width * o.height);
    const mjrRect viewport = {0, 0, o.width, o.height};
    std::size_t next = 0;
    for (std::size_t f = 0; f < o.times.size(); ++f) {
      while (next + 1 < samples.size() && samples[next + 1].time <= o.times[f]) ++next;
      const Sample& s = samples[next];
      mj_resetData(m, d);
      for (std::size_t c = 0; c < address.size(); ++c) d->qpos[address[c]] = s.values[c];
      mj_forward(m, d);
      camera.type = mjCAMERA_FREE;
      for (int i = 0; i < 3; ++i) camera.lookat[i] = d->site_xpos[3 * site + i];
      camera.distance = o.distance;
      camera.azimuth = o.azimuth;
      camera.elevation = o.elevation;
      mjv_updateScene(m, d, &option, nullptr, &camera, mjCAT_ALL, &scene);
      mjr_render(viewport, &scene, &context);
      mjr_readPixels(rgb.data(), nullptr, viewport, &context);
      char name[32];
      std::snprintf(name, sizeof(name), "_%03zu.ppm", f);
      writePpm(o.out + name, rgb, o.width, o.height);
    }
    mjr_freeContext(&context);
    mjv_freeScene(&scene);
    glfwDestroyWindow(window);
    glfwTerminate();
    mj_deleteData(d);
    mj_deleteModel(m);
    std::cout << "render_states: wrote " << o.times.size() << " frames " << o.out << "_000.ppm ...\n";
    return 0;
  } catch (const std::exception& e) {
    std::cerr << "render_states: " << e.what() << "\n";
    return 1;
  }
}
