// The ten development cases of the diagnosis (yaml/examples/diagnosis/V01–V10, made
// by an independent simulator with one effect each, answers in answer.json): the
// verdict's effect must be the case's, and its place where the case says (long: each
// case is a nominal fit, a screening and three refits of a 1 512-tet bar over 2.2 s).
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <ostream>
#include <regex>
#include <string>

#include "diagnose/diagnosis.hpp"
#include "diagnose/diagnosis_outputs.hpp"

namespace kelvin {
namespace {

namespace fs = std::filesystem;

struct Case {
  std::string dir, effect, where;  // where: "" = not judged
};
void PrintTo(const Case& c, std::ostream* os) {
  *os << c.dir;
}

/// The effect's type from answer.json (a flat search: the file is the generator's).
std::string answer_effect(const fs::path& dir) {
  std::ifstream in(dir / "answer.json");
  const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  std::smatch m;
  if (!std::regex_search(text, m, std::regex("\"type\"\\s*:\\s*\"([a-z_]+)\""))) return "";
  return m[1];
}

class DiagnosisSuite : public ::testing::TestWithParam<Case> {};

TEST_P(DiagnosisSuite, NamesTheCasesEffectWhereItIs) {
  const Case& c = GetParam();
  const fs::path dir = fs::path(KELVIN_SOURCE_DIR) / "yaml/examples/diagnosis" / c.dir;
  ASSERT_EQ(answer_effect(dir), c.effect);
  const fs::path out = fs::temp_directory_path() / ("kelvin-suite-" + c.dir);
  fs::remove_all(out);
  const Diagnosis d = run_diagnosis((dir / "train.yaml").string(), out.string(), {});
  write_diagnosis_outputs(d);
  EXPECT_EQ(d.effect, c.effect) << "report: " << (out / "report.md").string();
  if (!c.where.empty()) {
    ASSERT_FALSE(d.verdict_where.empty());
    EXPECT_EQ(d.verdict_where[0], c.where);
  }
}

INSTANTIATE_TEST_SUITE_P(
    Long, DiagnosisSuite,
    ::testing::Values(Case{"V01-none", "none", ""}, Case{"V02-stiffening", "stiffening", ""},
                      Case{"V03-damping-law", "damping_law", ""}, Case{"V04-drag", "drag", ""},
                      Case{"V05-inhomogeneity", "inhomogeneity", "clamp half"},
                      Case{"V06-added-mass", "added_mass", "free end"},
                      Case{"V07-anisotropy", "anisotropy", ""},
                      Case{"V08-clamp-compliance", "clamp_compliance", "clamp zone"},
                      Case{"V09-sync-lag", "sync_lag", ""},
                      Case{"V10-marker-offset", "marker_offset", "xa"}),
    [](const ::testing::TestParamInfo<Case>& info) {
      std::string name = info.param.dir;
      for (char& ch : name)
        if (ch == '-') ch = '_';
      return name;
    });

}  // namespace
}  // namespace kelvin
