#include "cmd/command.h"

#include "io/output_target.h"

#include <spdlog/fmt/fmt.h>

#include <cmath>
#include <fstream>
#include <iostream>
#include <sstream>

#include "core/error.h"
#include "io/bsdf_file.h"
#include "io/slice_export.h"
#include "job/job.h"
#include "scattering/components.h"

namespace mbsdf {
namespace {

std::vector<std::string> splitList(const std::string& s, bool skipEmpty) {
  std::vector<std::string> v;
  std::stringstream ss(s);
  for (std::string item; std::getline(ss, item, ',');)
    if (!(skipEmpty && item.empty())) v.push_back(item);
  return v;
}

}  // namespace

std::vector<std::string> parseModels(const std::string& s) {
  std::vector<std::string> models = splitList(s, true);
  for (const auto& m : models)
    if (!modelComponents(m)) throw InputError("--models: unknown model '" + m + "' (GS, GM, WS, WM or a component)");
  return models;
}

std::vector<double> parseAngles(const std::string& s, const std::string& option, double hi, bool hiInclusive) {
  std::vector<double> angles;
  for (const auto& item : splitList(s, false)) {
    size_t used = 0;
    double v = std::nan("");
    try {
      v = std::stod(item, &used);
    } catch (const std::exception&) {
    }
    if (used != item.size() || !(v >= 0 && (hiInclusive ? v <= hi : v < hi)))
      throw InputError(option + ": '" + item + "' is not an angle in [0, " + fmt::format("{}", hi) +
                       (hiInclusive ? "]" : ")"));
    angles.push_back(v);
  }
  return angles;
}

void warnIfIncomplete(const BsdfFileReader& f, const std::string& how) {
  if (f.doneCount() < f.incidenceCount())
    std::cerr << "warning: incomplete: " << f.doneCount() << " of " << f.incidenceCount() << " slices; " << how << "\n";
}

std::optional<Material> tableMaterial(const BsdfFileReader& f, const std::string& path) {
  if (!f.hasAttribute("job_text")) return std::nullopt;
  return loadMaterialFromString(f.attribute("job_text"), path + " (job_text)");
}

void writeJsonFile(const std::string& path, const nlohmann::json& j, int indent) {
  writeFileAtomically(path, j.dump(indent) + "\n");
}

std::string modelOrFullest(const BsdfFileReader& f, const std::string& model, const std::string& path) {
  if (!model.empty()) return model;
  const std::vector<std::string> models = availableModels(f);
  if (models.empty()) throw InputError(path + ": no model (GS, GM, WS, WM) can be formed from its components");
  return models.back();
}

void addThreadsOption(CLI::App* cmd, int& threads, const std::string& what) {
  cmd->add_option("--threads", threads, what)->check(CLI::NonNegativeNumber);
}

}  // namespace mbsdf
