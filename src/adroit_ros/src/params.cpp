#include "adroit_ros/params.h"

#include <ros/package.h>

#include <sstream>

#include "adroit_core/nearest_name.h"
#include "adroit_description/scenes.h"
#include "adroit_core/number_text.h"

namespace adroit::rosutil {

using adroit::shortNumber;

void Params::fail(const std::string& key, const std::string& what) const {
  throw ParameterError("bad parameter " + name(key) + ": " + what);
}

double Params::number(const std::string& key, double fallback) const {
  XmlRpc::XmlRpcValue v;
  if (!pnh_.getParam(key, v)) return fallback;
  if (v.getType() == XmlRpc::XmlRpcValue::TypeDouble) return static_cast<double>(v);
  if (v.getType() == XmlRpc::XmlRpcValue::TypeInt) return static_cast<int>(v);
  fail(key, "expected a number");
}

double Params::number(const std::string& key, double fallback, double lo, double hi) const {
  const double x = number(key, fallback);
  if (!(x >= lo && x <= hi)) fail(key, "must be in [" + shortNumber(lo) + ", " + shortNumber(hi) + "], got " + shortNumber(x));
  return x;
}

int Params::integer(const std::string& key, int fallback) const {
  XmlRpc::XmlRpcValue v;
  if (!pnh_.getParam(key, v)) return fallback;
  if (v.getType() != XmlRpc::XmlRpcValue::TypeInt) fail(key, "expected an integer");
  return static_cast<int>(v);
}

int Params::integer(const std::string& key, int fallback, int lo, int hi) const {
  const int x = integer(key, fallback);
  if (x < lo || x > hi)
    fail(key, "must be in [" + std::to_string(lo) + ", " + std::to_string(hi) + "], got " + std::to_string(x));
  return x;
}

bool Params::boolean(const std::string& key, bool fallback) const {
  XmlRpc::XmlRpcValue v;
  if (!pnh_.getParam(key, v)) return fallback;
  if (v.getType() != XmlRpc::XmlRpcValue::TypeBoolean) fail(key, "expected true or false");
  return static_cast<bool>(v);
}

std::string Params::string(const std::string& key, const std::string& fallback) const {
  XmlRpc::XmlRpcValue v;
  if (!pnh_.getParam(key, v)) return fallback;
  if (v.getType() != XmlRpc::XmlRpcValue::TypeString) fail(key, "expected a string");
  return static_cast<std::string>(v);
}

std::vector<std::string> Params::strings(const std::string& key) const {
  XmlRpc::XmlRpcValue v;
  std::vector<std::string> out;
  if (!pnh_.getParam(key, v)) return out;
  if (v.getType() != XmlRpc::XmlRpcValue::TypeArray) fail(key, "expected a list of names");
  for (int i = 0; i < v.size(); ++i) {
    if (v[i].getType() != XmlRpc::XmlRpcValue::TypeString) fail(key, "expected a list of names");
    out.push_back(static_cast<std::string>(v[i]));
  }
  return out;
}

void Params::checkKeys(const std::string& ns, const std::set<std::string>& allowed) const {
  XmlRpc::XmlRpcValue v;
  if (!pnh_.getParam(ns, v)) return;
  if (v.getType() != XmlRpc::XmlRpcValue::TypeStruct) fail(ns, "expected a map");
  for (const auto& kv : v) {
    if (!allowed.count(kv.first))
      fail(ns.empty() ? kv.first : ns + "/" + kv.first,
           "unknown parameter" + didYouMean(kv.first, std::vector<std::string>(allowed.begin(), allowed.end())));
  }
}

std::string Params::modelPath(const std::string& default_scene, bool planning) const {
  const std::string file = string("model_file", "");
  if (!file.empty()) return file;
  const std::string scene = string("scene", default_scene);
  const std::string share = ros::package::getPath("adroit_description");
  if (share.empty()) fail("scene", "package adroit_description not found");
  try {
    return description::sceneFile(share, scene, planning);
  } catch (const std::exception& e) {
    fail("scene", e.what());
  }
}

}  // namespace adroit::rosutil
