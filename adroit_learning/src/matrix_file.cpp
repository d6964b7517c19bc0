#include "adroit_learning/matrix_file.h"

#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <sstream>

namespace adroit {

namespace {

// Whitespace-separated tokens with their line numbers, comments removed.
struct Token {
  std::string text;
  int line;
};

std::vector<Token> tokenize(const std::string& text) {
  std::vector<Token> tokens;
  std::istringstream in(text);
  std::string line;
  for (int number = 1; std::getline(in, line); ++number) {
    const size_t hash = line.find('#');
    if (hash != std::string::npos) line.resize(hash);
    std::istringstream words(line);
    std::string word;
    while (words >> word) tokens.push_back({word, number});
  }
  return tokens;
}

bool parseInt(const std::string& s, long& out) {
  char* end = nullptr;
  errno = 0;
  out = std::strtol(s.c_str(), &end, 10);
  return errno == 0 && end != s.c_str() && *end == '\0';
}

}  // namespace

void MatrixFile::fail(const std::string& block, const std::string& problem) const {
  throw MatrixFileError(name_ + ": block '" + block + "': " + problem);
}

MatrixFile MatrixFile::read(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw MatrixFileError(path + ": cannot open for reading");
  std::ostringstream text;
  text << in.rdbuf();
  if (in.bad()) throw MatrixFileError(path + ": read error");
  return parse(text.str(), path);
}

MatrixFile MatrixFile::parse(const std::string& text, const std::string& name) {
  MatrixFile file(name);
  const std::vector<Token> tokens = tokenize(text);
  size_t i = 0;
  while (i < tokens.size()) {
    const Token& head = tokens[i];
    const std::string where = name + ":" + std::to_string(head.line) + ": block '" + head.text + "': ";
    long rows = 0, cols = 0;
    if (i + 2 >= tokens.size() || !parseInt(tokens[i + 1].text, rows) || !parseInt(tokens[i + 2].text, cols))
      throw MatrixFileError(where + "the header must be '<name> <rows> <cols>' with integer rows and cols");
    if (rows <= 0 || cols <= 0 || rows > 100000 || cols > 100000)
      throw MatrixFileError(where + "shape " + std::to_string(rows) + "x" + std::to_string(cols) +
                            " is not positive (or absurdly large)");
    if (file.has(head.text)) throw MatrixFileError(where + "appears twice");
    i += 3;
    Eigen::MatrixXd m(rows, cols);
    const long count = rows * cols;
    for (long n = 0; n < count; ++n, ++i) {
      if (i >= tokens.size())
        throw MatrixFileError(where + "the file ends after " + std::to_string(n) + " of its " +
                              std::to_string(count) + " numbers");
      const Token& tok = tokens[i];
      char* end = nullptr;
      const double v = std::strtod(tok.text.c_str(), &end);
      const std::string entry = "entry (" + std::to_string(n / cols) + ", " + std::to_string(n % cols) + ") on line " +
                                std::to_string(tok.line);
      if (end == tok.text.c_str() || *end != '\0')
        throw MatrixFileError(where + entry + " is not a number: '" + tok.text + "'" +
                              (n == 0 ? "" : " (too few numbers for the shape?)"));
      if (!std::isfinite(v)) throw MatrixFileError(where + entry + " is not finite: '" + tok.text + "'");
      m(n / cols, n % cols) = v;
    }
    file.set(head.text, m);
  }
  return file;
}

std::string MatrixFile::text() const {
  std::string out;
  char buf[64];
  for (const auto& [block, m] : blocks_) {
    out += block + " " + std::to_string(m.rows()) + " " + std::to_string(m.cols()) + "\n";
    for (Eigen::Index r = 0; r < m.rows(); ++r) {
      for (Eigen::Index c = 0; c < m.cols(); ++c) {
        std::snprintf(buf, sizeof buf, c == 0 ? "%.17g" : " %.17g", m(r, c));
        out += buf;
      }
      out += "\n";
    }
  }
  return out;
}

void MatrixFile::write(const std::string& path) const {
  std::ofstream out(path);
  if (!out) throw MatrixFileError(path + ": cannot open for writing");
  out << text();
  out.close();
  if (!out) throw MatrixFileError(path + ": write error");
}

const Eigen::MatrixXd& MatrixFile::get(const std::string& block) const {
  const auto it = index_.find(block);
  if (it == index_.end()) fail(block, "missing");
  return blocks_[it->second].second;
}

const Eigen::MatrixXd& MatrixFile::get(const std::string& block, int rows, int cols) const {
  const Eigen::MatrixXd& m = get(block);
  if (m.rows() != rows || m.cols() != cols)
    fail(block, "is " + std::to_string(m.rows()) + "x" + std::to_string(m.cols()) + ", expected " +
                    std::to_string(rows) + "x" + std::to_string(cols));
  return m;
}

void MatrixFile::set(const std::string& block, const Eigen::MatrixXd& value) {
  const auto it = index_.find(block);
  if (it != index_.end()) {
    blocks_[it->second].second = value;
    return;
  }
  index_[block] = blocks_.size();
  blocks_.emplace_back(block, value);
}

namespace {

void readDims(const MatrixFile& file, int& nx, int& nu, int& horizon) {
  const Eigen::MatrixXd& d = file.get("dims", 1, 3);
  for (int i = 0; i < 3; ++i)
    if (d(0, i) < 1 || d(0, i) != std::floor(d(0, i)) || d(0, i) > 1e6)
      throw MatrixFileError(file.name() + ": block 'dims': nx, nu and T must be positive integers");
  nx = static_cast<int>(d(0, 0));
  nu = static_cast<int>(d(0, 1));
  horizon = static_cast<int>(d(0, 2));
}

Eigen::MatrixXd dimsBlock(int nx, int nu, int horizon) {
  return (Eigen::MatrixXd(1, 3) << nx, nu, horizon).finished();
}

}  // namespace

LgDynamics readDynamics(const MatrixFile& file) {
  int nx, nu, T;
  readDims(file, nx, nu, T);
  LgDynamics d(nx, nu, T);
  d.x0_mean = file.get("x0_mean", nx, 1);
  d.x0_cov = file.get("x0_cov", nx, nx);
  for (int t = 0; t < T; ++t) {
    d.Fx[t] = file.get(MatrixFile::stepName("Fx", t), nx, nx);
    d.Fu[t] = file.get(MatrixFile::stepName("Fu", t), nx, nu);
    d.f[t] = file.get(MatrixFile::stepName("f", t), nx, 1);
    d.Sigma[t] = file.get(MatrixFile::stepName("Sigma", t), nx, nx);
  }
  return d;
}

QuadraticCost readCost(const MatrixFile& file, int nx, int nu, int T) {
  QuadraticCost c(nx, nu, T);
  for (int t = 0; t <= T; ++t) {
    c.cxx[t] = file.get(MatrixFile::stepName("cxx", t), nx, nx);
    c.cx[t] = file.get(MatrixFile::stepName("cx", t), nx, 1);
    if (t == T) break;
    c.cuu[t] = file.get(MatrixFile::stepName("cuu", t), nu, nu);
    c.cux[t] = file.get(MatrixFile::stepName("cux", t), nu, nx);
    c.cu[t] = file.get(MatrixFile::stepName("cu", t), nu, 1);
  }
  return c;
}

LgController readController(const MatrixFile& file, int nx, int nu, int T) {
  int fnx, fnu, fT;
  readDims(file, fnx, fnu, fT);
  if (fnx != nx || fnu != nu || fT != T)
    throw MatrixFileError(file.name() + ": block 'dims': the controller is nx=" + std::to_string(fnx) + " nu=" +
                          std::to_string(fnu) + " T=" + std::to_string(fT) + ", the dynamics nx=" +
                          std::to_string(nx) + " nu=" + std::to_string(nu) + " T=" + std::to_string(T));
  LgController c(nx, nu, T);
  for (int t = 0; t < T; ++t) {
    c.K[t] = file.get(MatrixFile::stepName("K", t), nu, nx);
    c.k[t] = file.get(MatrixFile::stepName("k", t), nu, 1);
    const std::string name = MatrixFile::stepName("C", t);
    try {
      c.setCovariance(t, file.get(name, nu, nu));
    } catch (const std::invalid_argument&) {
      throw MatrixFileError(file.name() + ": block '" + name + "': not a symmetric positive definite covariance");
    }
  }
  return c;
}

void writeDynamics(const LgDynamics& d, MatrixFile& file) {
  file.set("dims", dimsBlock(d.nx, d.nu, d.horizon));
  file.set("x0_mean", d.x0_mean);
  file.set("x0_cov", d.x0_cov);
  for (int t = 0; t < d.horizon; ++t) {
    file.set(MatrixFile::stepName("Fx", t), d.Fx[t]);
    file.set(MatrixFile::stepName("Fu", t), d.Fu[t]);
    file.set(MatrixFile::stepName("f", t), d.f[t]);
    file.set(MatrixFile::stepName("Sigma", t), d.Sigma[t]);
  }
}

void writeCost(const QuadraticCost& c, MatrixFile& file) {
  const int T = static_cast<int>(c.cuu.size());
  for (int t = 0; t <= T; ++t) {
    file.set(MatrixFile::stepName("cxx", t), c.cxx[t]);
    file.set(MatrixFile::stepName("cx", t), c.cx[t]);
    if (t == T) break;
    file.set(MatrixFile::stepName("cuu", t), c.cuu[t]);
    file.set(MatrixFile::stepName("cux", t), c.cux[t]);
    file.set(MatrixFile::stepName("cu", t), c.cu[t]);
  }
}

void writeController(const LgController& c, MatrixFile& file) {
  file.set("dims", dimsBlock(c.nx(), c.nu(), c.horizon()));
  for (int t = 0; t < c.horizon(); ++t) {
    file.set(MatrixFile::stepName("K", t), c.K[t]);
    file.set(MatrixFile::stepName("k", t), c.k[t]);
    file.set(MatrixFile::stepName("C", t), c.covariance(t));
  }
}

}  // namespace adroit
