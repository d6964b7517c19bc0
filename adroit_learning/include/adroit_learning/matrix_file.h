// A plain text file of named matrices, the exchange format of the kl_update tool.
//
//   # comment (to the end of the line)
//   <name> <rows> <cols>
//   <rows * cols numbers, row-major, separated by any whitespace or newlines>
//
// Names are single tokens; per-step blocks are called <name>.<t> (e.g. "Fx.3"). Numbers are
// C doubles; nan and inf are rejected. Every error names the file, the block and the
// problem (MatrixFileError). Files come from outside: only a regular file of at most
// kMaxMatrixFileBytes is read, and no block or horizon is allocated before the file is known
// to hold its numbers.
#pragma once

#include <adroit_core/bounded_file.h>
#include <adroit_learning/kl_update.h>
#include <adroit_learning/lg_controller.h>

#include <Eigen/Dense>
#include <map>
#include <stdexcept>
#include <string>
#include <vector>

namespace adroit {

class MatrixFileError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

constexpr std::size_t kMaxMatrixFileBytes = 256 * kMiB;
constexpr int kMaxMatrixDimension = 100000;  // rows, cols, nx, nu
constexpr int kMaxHorizon = 1000000;         // T of a dims block

class MatrixFile {
 public:
  MatrixFile() = default;
  explicit MatrixFile(std::string name) : name_(std::move(name)) {}

  static MatrixFile read(const std::string& path);   // throws MatrixFileError
  static MatrixFile parse(const std::string& text, const std::string& name);
  void write(const std::string& path) const;         // full precision (%.17g); throws MatrixFileError
  std::string text() const;

  const std::string& name() const { return name_; }  // the file name used in messages
  bool has(const std::string& block) const { return index_.count(block) != 0; }
  std::size_t blockCount() const { return blocks_.size(); }
  // The block, which must exist and have this shape (else MatrixFileError naming both).
  const Eigen::MatrixXd& get(const std::string& block, int rows, int cols) const;
  const Eigen::MatrixXd& get(const std::string& block) const;  // any shape
  void set(const std::string& block, const Eigen::MatrixXd& value);  // appends or replaces

  static std::string stepName(const std::string& base, int t) { return base + "." + std::to_string(t); }

 private:
  [[noreturn]] void fail(const std::string& block, const std::string& problem) const;
  std::string name_;
  std::vector<std::pair<std::string, Eigen::MatrixXd>> blocks_;  // file order
  std::map<std::string, size_t> index_;
};

// The 'dims' block (1x3: nx nu T): whole numbers in [1, kMaxMatrixDimension] (T: kMaxHorizon).
struct MatrixDims {
  int nx = 0, nu = 0, horizon = 0;
};
MatrixDims readDims(const MatrixFile& file);

// "" when `m` is a covariance (symmetric and positive semi-definite, both within rounding),
// else why not ("not positive semi-definite: its LDLT factorisation has the pivot -3.000000").
std::string covarianceProblem(const Eigen::MatrixXd& m);

// The tool's files (block names in README.md):
//   dynamics:   dims (1x3: nx nu T), x0_mean, x0_cov, Fx.t, Fu.t, f.t, Sigma.t (x0_cov and
//               Sigma.t must be covariances: covarianceProblem)
//   cost:       cxx.t, cx.t (t = 0..T, T = terminal), cuu.t, cux.t, cu.t (t < T)
//   controller: dims, K.t, k.t, C.t (C.t must be symmetric positive definite)
LgDynamics readDynamics(const MatrixFile& file);
QuadraticCost readCost(const MatrixFile& file, int nx, int nu, int horizon);
LgController readController(const MatrixFile& file, int nx, int nu, int horizon);
void writeDynamics(const LgDynamics& dyn, MatrixFile& file);
void writeCost(const QuadraticCost& cost, MatrixFile& file);
void writeController(const LgController& controller, MatrixFile& file);

}  // namespace adroit
