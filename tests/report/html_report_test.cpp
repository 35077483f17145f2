// The HTML report (report/html_report.h): the slider's incidences (finished ones, one azimuth, evenly
// spread, in order of θ) and a page that stays whole whatever the job's text holds (a comment with
// "</script>" or markup is shown as text, not run).
#include "report/html_report.h"

#include <gtest/gtest.h>

#include "../render/render_tables.h"

using namespace mbsdf;

namespace {

std::string lambertian(const std::string& name, const std::vector<double>& thetas,
                       const std::function<bool(int)>& written = {}, const std::string& comment = "") {
  return test::writeGreyTable(
      name, "n_theta = 6\nn_phi = 12", thetas,
      [](const Vec3&, int b, const DirectionGrid& g) { return g.isUpper(b) ? 1 / kPi : 0.0; }, true, written, comment);
}

}  // namespace

TEST(HtmlReport, SliderIncidencesAreFinishedSpreadAndOrdered) {
  std::vector<double> thetas;
  for (double t = 85; t > 0; t -= 2) thetas.push_back(t);  // descending in the file
  const BsdfFileReader file(lambertian("report-incidences", thetas, [](int i) { return i != 3; }));
  const std::vector<int> all = reportIncidences(file, 1000);
  EXPECT_EQ(all.size(), thetas.size() - 1);
  for (size_t k = 1; k < all.size(); ++k) EXPECT_LT(file.incidenceTheta(all[k - 1]), file.incidenceTheta(all[k]));
  for (int i : all) EXPECT_TRUE(file.done(i));
  const std::vector<int> few = reportIncidences(file, 5);
  ASSERT_EQ(few.size(), 5u);
  EXPECT_EQ(few.front(), all.front());  // the ends are kept
  EXPECT_EQ(few.back(), all.back());
}

TEST(HtmlReport, PageIsWholeWhateverTheJobTextHolds) {
  const BsdfFileReader file(
      lambertian("report-page", {10.0, 40.0, 70.0}, {}, "</script><script>alert('job')</script> <b>bold</b>"));
  ReportRequest req;
  req.sliceSize = 32;
  req.renderSize = 0;
  const std::string html = htmlReport(file, "a <b>&\"name\".h5", req);
  // One script block of data and the two of code, each closed once.
  size_t opens = 0, closes = 0;
  for (size_t p = 0; (p = html.find("<script", p)) != std::string::npos; ++p) ++opens;
  for (size_t p = 0; (p = html.find("</script>", p)) != std::string::npos; ++p) ++closes;
  EXPECT_EQ(opens, 3u);
  EXPECT_EQ(closes, 3u);
  EXPECT_NE(html.find("a &lt;b&gt;&amp;&quot;name&quot;.h5"), std::string::npos);
  EXPECT_EQ(html.find("<b>"), std::string::npos);
  EXPECT_NE(html.find("&lt;/script&gt;&lt;script&gt;alert(&#39;job&#39;)"), std::string::npos)
      << "the job's text as text";
  EXPECT_NE(html.find("data:image/png;base64,iVBORw0KGgo"), std::string::npos) << "PNG pictures inline";
}
