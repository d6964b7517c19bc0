#include "adroit_learning/matrix_file.h"

#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>

namespace adroit {

namespace {

// Whitespace-separated tokens of a text with their line numbers, comments skipped. Reads in
// place: a file costs its text and its blocks, not a string per number.
class Tokens {
 public:
  explicit Tokens(const std::string& text) : text_(text) {}
  // The next token, or false at the end of the text.
  bool next(std::string& token, int& line) {
    while (pos_ < text_.size()) {
      const char c = text_[pos_];
      if (c == '#') {
        while (pos_ < text_.size() && text_[pos_] != '\n') ++pos_;
      } else if (std::isspace(static_cast<unsigned char>(c))) {
        if (c == '\n') ++line_;
        ++pos_;
      } else {
        break;
      }
    }
    if (pos_ >= text_.size()) return false;
    const size_t begin = pos_;
    while (pos_ < text_.size() && !std::isspace(static_cast<unsigned char>(text_[pos_])) && text_[pos_] != '#') ++pos_;
    token.assign(text_, begin, pos_ - begin);
    line = line_;
    return true;
  }
  size_t bytesLeft() const { return text_.size() - pos_; }

 private:
  const std::string& text_;
  size_t pos_ = 0;
  int line_ = 1;
};

bool parseInt(const std::string& s, long& out) {
  char* end = nullptr;
  errno = 0;
  out = std::strtol(s.c_str(), &end, 10);
  return errno == 0 && end != s.c_str() && *end == '\0';
}

bool isNumber(const std::string& s) {
  char* end = nullptr;
  std::strtod(s.c_str(), &end);
  return end != s.c_str() && *end == '\0';
}

// Why a header does not parse, naming the block it belongs to: a number where a header should
// start is the previous block's surplus, so that block is the one named.
std::string badHeader(const std::string& name, int line, const std::string& head, const std::string& previous,
                      const std::string& previous_shape) {
  const std::string at = name + ":" + std::to_string(line) + ": ";
  if (!isNumber(head))
    return at + "block '" + head + "': the header must be '<name> <rows> <cols>' with integer rows and cols";
  if (previous.empty())
    return at + "the number '" + head + "' where the first block header '<name> <rows> <cols>' should be";
  return at + "block '" + previous + "' (" + previous_shape + "): the number '" + head +
         "' follows its last number where the next header should be (more numbers than its shape?)";
}

}  // namespace

void MatrixFile::fail(const std::string& block, const std::string& problem) const {
  throw MatrixFileError(name_ + ": block '" + block + "': " + problem);
}

MatrixFile MatrixFile::read(const std::string& path) {
  try {
    return parse(readBoundedFile(path, kMaxMatrixFileBytes), path);
  } catch (const FileError& e) {
    throw MatrixFileError(e.what());
  }
}

MatrixFile MatrixFile::parse(const std::string& text, const std::string& name) {
  MatrixFile file(name);
  Tokens tokens(text);
  std::string head, rows_text, cols_text, number, previous, previous_shape;
  int line = 0, unused = 0;
  while (tokens.next(head, line)) {
    const std::string where = name + ":" + std::to_string(line) + ": block '" + head + "': ";
    long rows = 0, cols = 0;
    const bool complete = tokens.next(rows_text, unused) && tokens.next(cols_text, unused);
    if (isNumber(head) || !complete || !parseInt(rows_text, rows) || !parseInt(cols_text, cols))
      throw MatrixFileError(badHeader(name, line, head, previous, previous_shape));
    if (rows <= 0 || cols <= 0 || rows > kMaxMatrixDimension || cols > kMaxMatrixDimension)
      throw MatrixFileError(where + "shape " + std::to_string(rows) + "x" + std::to_string(cols) +
                            " is not positive (or over " + std::to_string(kMaxMatrixDimension) + " per side)");
    if (file.has(head)) throw MatrixFileError(where + "appears twice");
    // Each number takes at least 2 bytes (a digit and a separator): checked before allocating.
    const long count = rows * cols;
    if (static_cast<size_t>(count) > tokens.bytesLeft() / 2 + 1)
      throw MatrixFileError(where + "shape " + std::to_string(rows) + "x" + std::to_string(cols) + " needs " +
                            std::to_string(count) + " numbers, more than the " +
                            std::to_string(tokens.bytesLeft()) + " bytes after its header can hold");
    Eigen::MatrixXd m(rows, cols);
    for (long n = 0; n < count; ++n) {
      int number_line = 0;
      if (!tokens.next(number, number_line))
        throw MatrixFileError(where + "the file ends after " + std::to_string(n) + " of its " +
                              std::to_string(count) + " numbers");
      char* end = nullptr;
      const double v = std::strtod(number.c_str(), &end);
      const std::string entry = "entry (" + std::to_string(n / cols) + ", " + std::to_string(n % cols) + ") on line " +
                                std::to_string(number_line);
      if (end == number.c_str() || *end != '\0')
        throw MatrixFileError(where + entry + " is not a number: '" + number + "'" +
                              (n == 0 ? "" : " (too few numbers for the shape?)"));
      if (!std::isfinite(v)) throw MatrixFileError(where + entry + " is not finite: '" + number + "'");
      m(n / cols, n % cols) = v;
    }
    file.set(head, m);
    previous = head;
    previous_shape = std::to_string(rows) + "x" + std::to_string(cols);
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

MatrixDims readDims(const MatrixFile& file) {
  const Eigen::MatrixXd& d = file.get("dims", 1, 3);
  const double limits[3] = {kMaxMatrixDimension, kMaxMatrixDimension, kMaxHorizon};
  for (int i = 0; i < 3; ++i)
    if (!(d(0, i) >= 1 && d(0, i) <= limits[i]) || d(0, i) != std::floor(d(0, i)))
      throw MatrixFileError(file.name() + ": block 'dims': nx, nu and T must be whole numbers in [1, " +
                            std::to_string(kMaxMatrixDimension) + "] (T: [1, " + std::to_string(kMaxHorizon) +
                            "]), got " + std::to_string(d(0, 0)) + " " + std::to_string(d(0, 1)) + " " +
                            std::to_string(d(0, 2)));
  return {static_cast<int>(d(0, 0)), static_cast<int>(d(0, 1)), static_cast<int>(d(0, 2))};
}

std::string covarianceProblem(const Eigen::MatrixXd& m) {
  if (m.rows() != m.cols()) return "not square";
  const double scale = m.cwiseAbs().maxCoeff(), tolerance = 1e-9 * scale;
  Eigen::Index r = 0, c = 0;
  const double asymmetry = (m - m.transpose()).cwiseAbs().maxCoeff(&r, &c);
  if (asymmetry > tolerance)
    return "not symmetric: entries (" + std::to_string(r) + ", " + std::to_string(c) + ") and (" + std::to_string(c) +
           ", " + std::to_string(r) + ") differ by " + std::to_string(asymmetry);
  // Pivoted LDLT: a semi-definite matrix has no pivot below zero (beyond rounding).
  const Eigen::LDLT<Eigen::MatrixXd> ldlt(m);
  const double pivot = ldlt.vectorD().minCoeff();
  if (ldlt.info() != Eigen::Success || pivot < -tolerance)
    return "not positive semi-definite: its LDLT factorisation has the pivot " + std::to_string(pivot);
  return "";
}

namespace {

Eigen::MatrixXd dimsBlock(int nx, int nu, int horizon) {
  return (Eigen::MatrixXd(1, 3) << nx, nu, horizon).finished();
}

struct StepBlock {
  const char* base;
  int rows, cols, extra_steps;  // extra_steps: 1 for blocks with a terminal step T
};

// Every per-step block exists with its shape, checked before anything of the horizon's size is
// allocated: a dims block's T cannot claim more memory than the file's own blocks hold.
void requireSteps(const MatrixFile& file, int horizon, std::initializer_list<StepBlock> blocks) {
  std::size_t needed = 0;
  for (const auto& b : blocks) needed += static_cast<std::size_t>(horizon + b.extra_steps);
  if (needed > file.blockCount())
    throw MatrixFileError(file.name() + ": T = " + std::to_string(horizon) + " needs " + std::to_string(needed) +
                          " per-step blocks, the file has " + std::to_string(file.blockCount()) + " blocks in all");
  for (const auto& b : blocks)
    for (int t = 0; t < horizon + b.extra_steps; ++t) file.get(MatrixFile::stepName(b.base, t), b.rows, b.cols);
}

void requireCovariance(const MatrixFile& file, const std::string& block) {
  const std::string problem = covarianceProblem(file.get(block));
  if (!problem.empty()) throw MatrixFileError(file.name() + ": block '" + block + "': " + problem);
}

}  // namespace

LgDynamics readDynamics(const MatrixFile& file) {
  const auto [nx, nu, T] = readDims(file);
  file.get("x0_mean", nx, 1);
  file.get("x0_cov", nx, nx);
  requireSteps(file, T, {{"Fx", nx, nx, 0}, {"Fu", nx, nu, 0}, {"f", nx, 1, 0}, {"Sigma", nx, nx, 0}});
  requireCovariance(file, "x0_cov");
  for (int t = 0; t < T; ++t) requireCovariance(file, MatrixFile::stepName("Sigma", t));
  LgDynamics d(nx, nu, T);
  d.x0_mean = file.get("x0_mean");
  d.x0_cov = file.get("x0_cov");
  for (int t = 0; t < T; ++t) {
    d.Fx[t] = file.get(MatrixFile::stepName("Fx", t));
    d.Fu[t] = file.get(MatrixFile::stepName("Fu", t));
    d.f[t] = file.get(MatrixFile::stepName("f", t));
    d.Sigma[t] = file.get(MatrixFile::stepName("Sigma", t));
  }
  return d;
}

QuadraticCost readCost(const MatrixFile& file, int nx, int nu, int T) {
  requireSteps(file, T, {{"cxx", nx, nx, 1}, {"cx", nx, 1, 1}, {"cuu", nu, nu, 0}, {"cux", nu, nx, 0}, {"cu", nu, 1, 0}});
  QuadraticCost c(nx, nu, T);
  for (int t = 0; t <= T; ++t) {
    c.cxx[t] = file.get(MatrixFile::stepName("cxx", t));
    c.cx[t] = file.get(MatrixFile::stepName("cx", t));
    if (t == T) break;
    c.cuu[t] = file.get(MatrixFile::stepName("cuu", t));
    c.cux[t] = file.get(MatrixFile::stepName("cux", t));
    c.cu[t] = file.get(MatrixFile::stepName("cu", t));
  }
  return c;
}

LgController readController(const MatrixFile& file, int nx, int nu, int T) {
  const MatrixDims dims = readDims(file);
  if (dims.nx != nx || dims.nu != nu || dims.horizon != T)
    throw MatrixFileError(file.name() + ": block 'dims': the controller is nx=" + std::to_string(dims.nx) + " nu=" +
                          std::to_string(dims.nu) + " T=" + std::to_string(dims.horizon) + ", the dynamics nx=" +
                          std::to_string(nx) + " nu=" + std::to_string(nu) + " T=" + std::to_string(T));
  requireSteps(file, T, {{"K", nu, nx, 0}, {"k", nu, 1, 0}, {"C", nu, nu, 0}});
  LgController c(nx, nu, T);
  for (int t = 0; t < T; ++t) {
    c.K[t] = file.get(MatrixFile::stepName("K", t));
    c.k[t] = file.get(MatrixFile::stepName("k", t));
    const std::string name = MatrixFile::stepName("C", t);
    try {
      c.setCovariance(t, file.get(name));
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
