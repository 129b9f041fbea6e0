#include "ct/ct_volume.h"

#include <gdcmAttribute.h>
#include <gdcmImageChangeTransferSyntax.h>
#include <gdcmImageReader.h>
#include <gdcmImageWriter.h>
#include <gdcmReader.h>
#include <gdcmSequenceOfFragments.h>
#include <gdcmWriter.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iostream>
#include <random>

#include "ct/ct_phantom.h"
#include "ct/ct_simulate.h"
#include "ct/ct_test_util.h"

namespace carmba {
namespace {

namespace fs = std::filesystem;
using testing::ScratchDir;
using testing::WriteText;

const std::string kPydicom =
    "/usr/lib/python3/dist-packages/pydicom/data/test_files/dicomdirtests/";
const std::string kCt5n = kPydicom + "98892001/CT5N";
const std::string kCt2n = kPydicom + "98892001/CT2N";
const std::string kCt2 = kPydicom + "77654033/CT2";

bool HavePydicom() { return fs::is_directory(kCt5n) && fs::is_directory(kCt2); }

// A small written series (noisy phantom) into `dir`; returns the volume written.
CtVolume WriteSmallSeries(const std::string& dir, double tilt_deg = 0, int slices = 10) {
  const double t = tilt_deg * M_PI / 180;
  CtVolume v = MakeCtGeometry(20, 16, slices, 0.5, 0.8, 0, Eigen::Vector3d::UnitX(),
                              Eigen::Vector3d(0, std::cos(t), std::sin(t)),
                              Eigen::Vector3d(1, 2, 3));
  CtPhantom ph;
  ph.markers = {CtMarker{1, Eigen::Vector3d(1.2, 2.1, 3.3)}};
  ph.block_min_mm = Eigen::Vector3d(-2, -1, 0);
  ph.block_max_mm = Eigen::Vector3d(4, 5, 6);
  CtVoxeliseOptions vo;
  EXPECT_TRUE(VoxelisePhantom(ph, vo, &v).ok());
  CtWriteOptions wo;
  wo.study_uid = "2.25.1.1";
  wo.series_uid = "2.25.1.2";
  wo.frame_of_reference_uid = "2.25.1.3";
  const Status s = WriteCtSeries(v, dir, wo);
  EXPECT_TRUE(s.ok()) << s.message();
  return v;
}

std::vector<std::string> Files(const std::string& dir) {
  std::vector<std::string> f;
  for (const auto& e : fs::directory_iterator(dir)) f.push_back(e.path().string());
  std::sort(f.begin(), f.end());
  return f;
}

// Rewrites one DICOM file after `edit` changed its data set.
void EditDicom(const std::string& path, const std::function<void(gdcm::DataSet*)>& edit) {
  gdcm::Reader r;
  r.SetFileName(path.c_str());
  ASSERT_TRUE(r.Read());
  gdcm::File& file = r.GetFile();  // owned by the reader (Writer keeps a reference count)
  edit(&file.GetDataSet());
  gdcm::Writer w;
  w.SetFile(file);
  w.SetFileName(path.c_str());
  ASSERT_TRUE(w.Write());
}

void SetString(gdcm::DataSet* ds, uint16_t g, uint16_t e, gdcm::VR vr, std::string v) {
  if (v.size() % 2) v.push_back(' ');
  gdcm::DataElement de(gdcm::Tag(g, e));
  de.SetVR(vr);
  de.SetByteValue(v.data(), static_cast<uint32_t>(v.size()));
  ds->Replace(de);
}

void ExpectError(const StatusOr<CtVolume>& r, const std::vector<std::string>& parts) {
  ASSERT_FALSE(r.ok());
  for (const auto& p : parts) {
    EXPECT_NE(r.status().message().find(p), std::string::npos)
        << "'" << p << "' not in: " << r.status().message();
  }
  EXPECT_EQ(r.status().message().find('\n'), std::string::npos);
}

TEST(CtRead, RealPydicomFiveSliceSeriesSortedByPositionNotByName) {
  if (!HavePydicom()) GTEST_SKIP() << "python3-pydicom test files not installed";
  auto v = ReadCtSeries(kCt5n);
  ASSERT_TRUE(v.ok()) << v.status().message();
  EXPECT_EQ(v->columns, 16);
  EXPECT_EQ(v->rows, 16);
  EXPECT_EQ(v->slices, 5);
  constexpr double kDsTol = 1e-5;  // DS values printed with 6 decimals
  EXPECT_NEAR(v->spacing_mm.z(), 2.5, kDsTol);
  EXPECT_NEAR(v->spacing_mm.x(), 0.488281, kDsTol);
  // Sorted by position along the normal (+z): file 3353 (z = -1.2375) first, 2062 (8.7625) last,
  // although InstanceNumber and file names run the other way.
  EXPECT_NEAR(v->origin_mm.z(), -1.2375, kDsTol);
  EXPECT_EQ(fs::path(v->files.front()).filename(), "3353");
  EXPECT_EQ(fs::path(v->files.back()).filename(), "2062");
  EXPECT_NEAR((v->axes - Eigen::Matrix3d::Identity()).norm(), 0, kDsTol);
  // The voxels are the file's stored values rescaled (slope 1, intercept -1024).
  gdcm::ImageReader r;
  r.SetFileName(v->files.back().c_str());
  ASSERT_TRUE(r.Read());
  std::vector<char> raw(r.GetImage().GetBufferLength());
  ASSERT_TRUE(r.GetImage().GetBuffer(raw.data()));
  const auto* p = reinterpret_cast<const uint16_t*>(raw.data());
  if (r.GetImage().GetPixelFormat().GetPixelRepresentation() == 1) {
    EXPECT_FLOAT_EQ(v->At(5, 7, 4), reinterpret_cast<const int16_t*>(p)[7 * 16 + 5] - 1024.0f);
  } else {
    EXPECT_FLOAT_EQ(v->At(5, 7, 4), p[7 * 16 + 5] - 1024.0f);
  }
}

TEST(CtRead, RealPydicomUnevenSeriesIsRefusedNamingTheGap) {
  if (!HavePydicom()) GTEST_SKIP() << "python3-pydicom test files not installed";
  ExpectError(ReadCtSeries(kCt2), {"gap of 202.500 mm", "17106", "17136", "expected 1.250 mm",
                                   "slices missing"});
}

TEST(CtRead, MixedSeriesRefusedUnlessOneIsSelected) {
  if (!HavePydicom()) GTEST_SKIP() << "python3-pydicom test files not installed";
  ScratchDir dir("mixed");
  for (const auto& f : Files(kCt5n)) fs::copy(f, dir.File("a" + fs::path(f).filename().string()));
  for (const auto& f : Files(kCt2)) fs::copy(f, dir.File("b" + fs::path(f).filename().string()));
  ExpectError(ReadCtSeries(dir.path()),
              {"2 series mixed", "1.3.6.1.4.1.5962.1.1.0.0.0.1194734704.16302.0.6 (5 files)"});
  CtReadOptions opt;
  opt.series_uid = "1.3.6.1.4.1.5962.1.1.0.0.0.1194734704.16302.0.6";
  auto v = ReadCtSeries(dir.path(), opt);
  ASSERT_TRUE(v.ok()) << v.status().message();
  EXPECT_EQ(v->slices, 5);
  opt.series_uid = "1.2.3";
  ExpectError(ReadCtSeries(dir.path(), opt), {"no series with SeriesInstanceUID '1.2.3'"});
}

TEST(CtRead, RealPydicomSeriesWithTwoOrientationsIsRefused) {
  if (!fs::is_directory(kCt2n)) GTEST_SKIP() << "python3-pydicom test files not installed";
  auto v = ReadCtSeries(kCt2n);
  ASSERT_FALSE(v.ok());
  EXPECT_EQ(v.status().message().find('\n'), std::string::npos);
}

TEST(CtRead, ShuffledRenamedFilesGiveTheSameVolume) {
  ScratchDir dir("shuffle");
  const CtVolume written = WriteSmallSeries(dir.File("a"), 12);
  auto a = ReadCtSeries(dir.File("a"));
  ASSERT_TRUE(a.ok()) << a.status().message();
  fs::create_directories(dir.File("b"));
  auto files = Files(dir.File("a"));
  std::mt19937 rng(3);
  std::shuffle(files.begin(), files.end(), rng);
  for (size_t i = 0; i < files.size(); ++i) {
    fs::copy(files[i], dir.File("b/IM" + std::to_string(1000 - 7 * i)));
  }
  WriteText(dir.File("b/README.txt"), "not a DICOM file\n");
  std::vector<std::string> skipped;
  auto b = ReadCtSeries(dir.File("b"), CtReadOptions(), &skipped);
  ASSERT_TRUE(b.ok()) << b.status().message();
  EXPECT_EQ(skipped.size(), 1u);
  EXPECT_EQ(a->hu, b->hu);
  EXPECT_NEAR((a->origin_mm - written.origin_mm).norm(), 0, 1e-6);
  EXPECT_NEAR((b->axes - written.axes).norm(), 0, 1e-6);
}

TEST(CtRead, CompressedSeriesDecodesToTheSameVolume) {
  ScratchDir dir("rle");
  WriteSmallSeries(dir.File("raw"));
  fs::create_directories(dir.File("rle"));
  for (const auto& f : Files(dir.File("raw"))) {
    gdcm::ImageReader r;
    r.SetFileName(f.c_str());
    ASSERT_TRUE(r.Read());
    gdcm::ImageChangeTransferSyntax change;
    change.SetTransferSyntax(gdcm::TransferSyntax::RLELossless);
    change.SetInput(r.GetImage());
    ASSERT_TRUE(change.Change());
    gdcm::ImageWriter w;
    w.SetFile(r.GetFile());
    w.SetImage(change.GetOutput());
    const std::string out = dir.File("rle/" + fs::path(f).filename().string());
    w.SetFileName(out.c_str());
    ASSERT_TRUE(w.Write());
  }
  auto raw = ReadCtSeries(dir.File("raw"));
  auto rle = ReadCtSeries(dir.File("rle"));
  ASSERT_TRUE(raw.ok() && rle.ok()) << rle.status().message();
  EXPECT_EQ(raw->hu, rle->hu);
}

// Bad inputs, one corruption at a time.
TEST(CtRead, EmptyOrNonDicomDirectoryIsRefused) {
  ScratchDir dir("empty");
  ExpectError(ReadCtSeries(dir.path()), {"no DICOM image files"});
  WriteText(dir.File("notes.txt"), "hello\n");
  ExpectError(ReadCtSeries(dir.path()), {"no DICOM image files", "1 files looked at"});
  ExpectError(ReadCtSeries(dir.File("missing")), {"missing", "not a directory"});
}

TEST(CtRead, MissingSliceIsRefusedNamingTheGap) {
  ScratchDir dir("gap");
  WriteSmallSeries(dir.path());
  fs::remove(dir.File("slice_0005.dcm"));
  ExpectError(ReadCtSeries(dir.path()),
              {"gap of 1.600 mm", "slice_0004.dcm", "slice_0006.dcm", "expected 0.800 mm",
               "about 1 slices missing"});
}

TEST(CtRead, DuplicateSliceIsRefused) {
  ScratchDir dir("dup");
  WriteSmallSeries(dir.path());
  fs::copy(dir.File("slice_0003.dcm"), dir.File("copy_of_3.dcm"));
  ExpectError(ReadCtSeries(dir.path()), {"two slices at the same position"});
}

TEST(CtRead, InconsistentOrientationIsRefused) {
  ScratchDir dir("orient");
  WriteSmallSeries(dir.path());
  EditDicom(dir.File("slice_0004.dcm"), [](gdcm::DataSet* ds) {
    SetString(ds, 0x0020, 0x0037, gdcm::VR::DS, "1\\0\\0\\0\\0.9998476952\\0.0174524064");
  });
  ExpectError(ReadCtSeries(dir.path()), {"slice_0004.dcm", "inconsistent orientation"});
}

TEST(CtRead, InconsistentSizeIsRefused) {
  ScratchDir dir("size");
  WriteSmallSeries(dir.File("a"));
  CtVolume other = MakeCtGeometry(24, 16, 1, 0.5, 0.8, 0, Eigen::Vector3d::UnitX(),
                                   Eigen::Vector3d::UnitY(), Eigen::Vector3d(0, 0, 50));
  other.hu.assign(24 * 16, 0.0f);
  CtWriteOptions wo;
  wo.study_uid = "2.25.1.1";
  wo.series_uid = "2.25.1.2";  // the same series
  wo.frame_of_reference_uid = "2.25.1.3";
  ASSERT_TRUE(WriteCtSeries(other, dir.File("b"), wo).ok());
  fs::copy(dir.File("b/slice_0001.dcm"), dir.File("a/extra.dcm"));
  ExpectError(ReadCtSeries(dir.File("a")), {"20x16 pixels", "has 24x16"});
}

TEST(CtRead, InPlaneShiftIsRefused) {
  ScratchDir dir("shift");
  const CtVolume v = WriteSmallSeries(dir.path());
  EditDicom(dir.File("slice_0006.dcm"), [&](gdcm::DataSet* ds) {
    const Eigen::Vector3d p = v.PatientFromIndex(Eigen::Vector3d(0, 0, 5)) +
                              Eigen::Vector3d(0.7, 0, 0);
    SetString(ds, 0x0020, 0x0032, gdcm::VR::DS,
              FormatDicomDecimal(p.x()) + "\\" + FormatDicomDecimal(p.y()) + "\\" +
                  FormatDicomDecimal(p.z()));
  });
  ExpectError(ReadCtSeries(dir.path()), {"inconsistent in-plane offset", "slice_0006.dcm"});
}

TEST(CtRead, MissingGeometryTagIsRefused) {
  ScratchDir dir("tag");
  WriteSmallSeries(dir.path());
  EditDicom(dir.File("slice_0002.dcm"),
            [](gdcm::DataSet* ds) { ds->Remove(gdcm::Tag(0x0028, 0x0030)); });
  ExpectError(ReadCtSeries(dir.path()), {"slice_0002.dcm", "PixelSpacing (0028,0030)"});
}

TEST(CtRead, TruncatedFileIsRefusedNamingIt) {
  // Cut inside the preamble's meta group, inside element headers and values, at an element
  // boundary before the pixel data, and inside the pixel data. (GDCM alone aborts on several.)
  for (int size : {136, 150, 200, 300, 400, 600, 700, 800, 1000, 1100}) {
    ScratchDir dir("trunc");
    WriteSmallSeries(dir.path());
    fs::resize_file(dir.File("slice_0007.dcm"), size);
    ExpectError(ReadCtSeries(dir.path()), {"slice_0007.dcm", "corrupt DICOM"});
  }
}

TEST(CtRead, UndecodableCompressedPixelDataIsRefused) {
  ScratchDir dir("jpeg");
  WriteSmallSeries(dir.path());
  // Declare JPEG 2000 and replace the pixel data by a fragment of garbage.
  const std::string path = dir.File("slice_0003.dcm");
  gdcm::Reader r;
  r.SetFileName(path.c_str());
  ASSERT_TRUE(r.Read());
  gdcm::File& file = r.GetFile();  // owned by the reader (Writer keeps a reference count)
  gdcm::SmartPointer<gdcm::SequenceOfFragments> sq = new gdcm::SequenceOfFragments;
  gdcm::Fragment frag;
  const std::string garbage(64, '\x5a');
  frag.SetByteValue(garbage.data(), static_cast<uint32_t>(garbage.size()));
  sq->AddFragment(frag);
  gdcm::DataElement pixels(gdcm::Tag(0x7fe0, 0x0010));
  pixels.SetVR(gdcm::VR::OB);
  pixels.SetValue(*sq);
  file.GetDataSet().Replace(pixels);
  file.GetHeader().SetDataSetTransferSyntax(gdcm::TransferSyntax::JPEG2000Lossless);
  file.GetHeader().Remove(gdcm::Tag(0x0002, 0x0010));
  gdcm::Writer w;
  w.SetFile(file);
  w.SetFileName(path.c_str());
  ASSERT_TRUE(w.Write());
  ExpectError(ReadCtSeries(dir.path()), {"slice_0003.dcm", "cannot decode"});
}

// Every input that once made GDCM abort, crash or exhaust memory (tests/fuzz/seeds/regress, found
// by the fuzz harnesses) in a CT series directory: read, skipped or a one-line error naming the
// file, never the end of the process (the normal suite's Release build, Debian's GDCM).
TEST(CtRead, FuzzRegressionInputsAreOneLineErrors) {
  const std::filesystem::path regress =
      std::filesystem::path(CARMBA_SOURCE_DIR) / "tests/fuzz/seeds/regress";
  int files = 0, errors = 0;
  for (const auto& entry : std::filesystem::directory_iterator(regress)) {
    if (entry.path().extension() != ".dcm") continue;
    ++files;
    ScratchDir dir("regress");
    const std::string name = entry.path().filename().string();
    std::filesystem::copy_file(entry.path(), dir.File(name));
    const auto r = ReadCtSeries(dir.path());
    if (r.ok()) continue;
    const std::string& m = r.status().message();
    EXPECT_EQ(m.find('\n'), std::string::npos) << m;
    if (m.find(name) != std::string::npos) ++errors;  // else: skipped, "no DICOM image in ..."
  }
  std::cout << errors << " of " << files << " files refused naming the file\n";
  EXPECT_GE(files, 14);
  EXPECT_GE(errors, files - 1);
}

}  // namespace
}  // namespace carmba
