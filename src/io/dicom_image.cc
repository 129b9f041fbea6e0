#include "io/dicom_image.h"

#include <gdcmImage.h>
#include <gdcmPhotometricInterpretation.h>
#include <gdcmPixelFormat.h>
#include <gdcmReader.h>
#include <gdcmSequenceOfFragments.h>
#include <gdcmTransferSyntax.h>
#include <gdcmUIDs.h>

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <mutex>

#include "util/file_util.h"
#include "util/gdcm_util.h"
#include "util/plausible.h"
#include "util/quiet_stderr.h"

namespace carmba {

DicomImage::DicomImage() = default;
DicomImage::~DicomImage() = default;
DicomImage::DicomImage(DicomImage&&) noexcept = default;
DicomImage& DicomImage::operator=(DicomImage&&) noexcept = default;

const gdcm::DataSet& DicomImage::data_set() const { return reader->GetFile().GetDataSet(); }
const gdcm::FileMetaInformation& DicomImage::header() const {
  return reader->GetFile().GetHeader();
}

std::string TransferSyntaxName(const std::string& uid) {
  gdcm::UIDs u;
  if (u.SetFromUID(uid.c_str()) && u.GetName()) return uid + " (" + u.GetName() + ")";
  return uid + " (unknown to GDCM)";
}

namespace {

// Decoded images above this size are refused before anything is allocated (a corrupt Rows /
// Columns / Number of Frames would otherwise ask for terabytes): plausible::kImageBytes.
constexpr size_t kMaxPixelBytes = static_cast<size_t>(plausible::kImageBytes.hi);

std::string Tag(uint16_t g, uint16_t e) {
  char b[16];
  std::snprintf(b, sizeof(b), "(%04x,%04x)", g, e);
  return b;
}

// An unsigned short (US) element of the top-level data set: -1 when absent or empty; an error
// when its value is shorter than 2 bytes or not binary. (Explicit VRs were checked against the
// dictionary by gdcm_util::CheckDicomFile; GDCM delivers binary values in native byte order.)
Status GetUS(const gdcm::DataSet& ds, uint16_t g, uint16_t e, const std::string& what,
             const std::string& path, int* out) {
  *out = -1;
  const gdcm::Tag tag(g, e);
  if (!ds.FindDataElement(tag)) return Status::Ok();
  const gdcm::DataElement& de = ds.GetDataElement(tag);
  if (de.IsEmpty()) return Status::Ok();
  const gdcm::ByteValue* bv = de.GetByteValue();
  if (!bv || bv->GetLength() < 2) {
    return Status::Error(path + ": " + what + " " + Tag(g, e) + " is not a 2-byte value");
  }
  uint16_t v;
  std::memcpy(&v, bv->GetPointer(), 2);
  *out = v;
  return Status::Ok();
}

// Number of Frames (0028,0008), an integer string: 1 when absent or empty.
Status GetFrames(const gdcm::DataSet& ds, const std::string& path, int* out) {
  *out = 1;
  const std::string s = gdcm_util::GetString(ds, 0x0028, 0x0008);
  if (s.empty()) return Status::Ok();
  char* end = nullptr;
  const long v = std::strtol(s.c_str(), &end, 10);
  std::string shown;
  for (char c : s.substr(0, 32)) shown += (c >= 0x20 && c < 0x7f) ? c : '?';
  if (end == s.c_str() || *end != '\0' || v < 1 || v > 100000) {
    return Status::Error(path + ": Number of Frames (0028,0008) is '" + shown +
                         "', expected an integer from 1 to 100000");
  }
  *out = static_cast<int>(v);
  return Status::Ok();
}

// Reads the image pixel module of ds into *out (no pixels yet).
Status ReadPixelModule(const gdcm::DataSet& ds, const std::string& path,
                       const DicomImageOptions& options, DicomImage* out) {
  int spp, rows, cols, ba, bs, hb, pr;
  CARMBA_RETURN_IF_ERROR(GetUS(ds, 0x0028, 0x0002, "Samples per Pixel", path, &spp));
  CARMBA_RETURN_IF_ERROR(GetUS(ds, 0x0028, 0x0010, "Rows", path, &rows));
  CARMBA_RETURN_IF_ERROR(GetUS(ds, 0x0028, 0x0011, "Columns", path, &cols));
  CARMBA_RETURN_IF_ERROR(GetUS(ds, 0x0028, 0x0100, "Bits Allocated", path, &ba));
  CARMBA_RETURN_IF_ERROR(GetUS(ds, 0x0028, 0x0101, "Bits Stored", path, &bs));
  CARMBA_RETURN_IF_ERROR(GetUS(ds, 0x0028, 0x0102, "High Bit", path, &hb));
  CARMBA_RETURN_IF_ERROR(GetUS(ds, 0x0028, 0x0103, "Pixel Representation", path, &pr));
  CARMBA_RETURN_IF_ERROR(GetFrames(ds, path, &out->frames));
  out->photometric = gdcm_util::GetString(ds, 0x0028, 0x0004);
  if (spp < 0) spp = 1;
  if (spp != 1) {
    return Status::Error(path + ": Samples per Pixel (0028,0002) is " + std::to_string(spp) +
                         ", expected 1 (a monochrome image)");
  }
  if (rows <= 0 || cols <= 0) {
    return Status::Error(path + ": Rows (0028,0010) " +
                         (rows < 0 ? std::string("absent") : std::to_string(rows)) +
                         ", Columns (0028,0011) " +
                         (cols < 0 ? std::string("absent") : std::to_string(cols)) +
                         ": expected an image of at least 1 x 1 px");
  }
  if (ba < 0) {
    return Status::Error(path + ": no Bits Allocated (0028,0100), expected 8 or 16" +
                         (options.allow_32_bit ? std::string(" or 32") : std::string()));
  }
  if (ba != 8 && ba != 16 && !(options.allow_32_bit && ba == 32)) {
    return Status::Error(path + ": Bits Allocated (0028,0100) is " + std::to_string(ba) +
                         ", expected 8 or 16" +
                         (options.allow_32_bit ? std::string(" or 32") : std::string()));
  }
  if (bs < 0) bs = ba;
  if (hb < 0) hb = bs - 1;
  if (bs < 1 || bs > ba || hb + 1 < bs || hb >= ba) {
    return Status::Error(path + ": Bits Stored (0028,0101) " + std::to_string(bs) +
                         " / High Bit (0028,0102) " + std::to_string(hb) +
                         " inconsistent with Bits Allocated " + std::to_string(ba));
  }
  if (pr > 1) {
    return Status::Error(path + ": Pixel Representation (0028,0103) is " + std::to_string(pr) +
                         ", expected 0 (unsigned) or 1 (signed)");
  }
  out->rows = rows;
  out->columns = cols;
  out->bits_allocated = ba;
  out->bits_stored = bs;
  out->high_bit = hb;
  out->is_signed = pr == 1;
  return Status::Ok();
}

// What the decoder needs besides the file: the image pixel module as read by ReadPixelModule.
struct DecodeRequest {
  uint32_t magic = 0x43444331;  // "CDC1"
  int32_t rows = 0, columns = 0, frames = 0, bits_allocated = 0, bits_stored = 0, high_bit = 0;
  int32_t is_signed = 0, photometric = 0, transfer_syntax = 0;
  uint64_t expected = 0;
  uint32_t path_length = 0;
};
struct DecodeResponse {
  uint32_t ok = 0;
  uint64_t length = 0;
};

bool WriteAll(int fd, const void* data, size_t n) {
  const char* p = static_cast<const char*>(data);
  while (n > 0) {
    const ssize_t w = ::send(fd, p, n, MSG_NOSIGNAL);
    if (w < 0 && errno == EINTR) continue;
    if (w <= 0) return false;
    p += w;
    n -= static_cast<size_t>(w);
  }
  return true;
}

// Reads n bytes; with a deadline (steady clock) when `deadline` is given. *timed_out on expiry.
bool ReadAll(int fd, void* data, size_t n,
             const std::chrono::steady_clock::time_point* deadline = nullptr,
             bool* timed_out = nullptr) {
  char* p = static_cast<char*>(data);
  while (n > 0) {
    if (deadline) {
      const double left_ms = std::chrono::duration<double, std::milli>(
                                 *deadline - std::chrono::steady_clock::now())
                                 .count();
      if (left_ms <= 0) {
        if (timed_out) *timed_out = true;
        return false;
      }
      pollfd pfd = {fd, POLLIN, 0};
      const int r = ::poll(&pfd, 1, static_cast<int>(left_ms) + 1);
      if (r < 0 && errno == EINTR) continue;
      if (r == 0) continue;  // re-check the deadline
      if (r < 0) return false;
    }
    const ssize_t got = ::read(fd, p, n);
    if (got < 0 && errno == EINTR) continue;
    if (got <= 0) return false;
    p += got;
    n -= static_cast<size_t>(got);
  }
  return true;
}

// The gdcm::Image a codec decodes: the pixel module as read by ReadPixelModule and the pixel data.
gdcm::SmartPointer<gdcm::Image> ImageFor(const DecodeRequest& r, const gdcm::DataElement& pixels) {
  gdcm::SmartPointer<gdcm::Image> image = new gdcm::Image;
  image->SetNumberOfDimensions(r.frames > 1 ? 3 : 2);
  image->SetDimension(0, static_cast<unsigned int>(r.columns));
  image->SetDimension(1, static_cast<unsigned int>(r.rows));
  if (r.frames > 1) image->SetDimension(2, static_cast<unsigned int>(r.frames));
  image->SetPixelFormat(gdcm::PixelFormat(1, static_cast<unsigned short>(r.bits_allocated),
                                          static_cast<unsigned short>(r.bits_stored),
                                          static_cast<unsigned short>(r.high_bit),
                                          r.is_signed ? 1 : 0));
  image->SetPhotometricInterpretation(
      static_cast<gdcm::PhotometricInterpretation::PIType>(r.photometric));
  image->SetTransferSyntax(static_cast<gdcm::TransferSyntax::TSType>(r.transfer_syntax));
  image->SetDataElement(pixels);
  return image;
}

// The decoder process's loop: a request (and the file's path) in, the decoded pixels out. The
// file is parsed again here (it passed the parent's structure check), so that no GDCM object
// crosses the process boundary.
[[noreturn]] void DecoderLoop(int fd) {
  while (true) {
    DecodeRequest r;
    if (!ReadAll(fd, &r, sizeof(r)) || r.magic != DecodeRequest().magic) ::_exit(0);
    std::string path(r.path_length, '\0');
    if (!ReadAll(fd, &path[0], path.size())) ::_exit(0);
    std::vector<char> pixels;
    bool ok = false;
    gdcm::Reader reader;
    reader.SetFileName(path.c_str());
    if (reader.Read() && reader.GetFile().GetDataSet().FindDataElement(gdcm::Tag(0x7fe0, 0x0010))) {
      gdcm::SmartPointer<gdcm::Image> image = ImageFor(
          r, reader.GetFile().GetDataSet().GetDataElement(gdcm::Tag(0x7fe0, 0x0010)));
      if (image->GetBufferLength() == r.expected) {
        pixels.resize(r.expected);
        ok = image->GetBuffer(pixels.data());
      }
    }
    DecodeResponse resp;
    resp.ok = ok ? 1 : 0;
    resp.length = ok ? pixels.size() : 0;
    if (!WriteAll(fd, &resp, sizeof(resp))) ::_exit(0);
    if (ok && !WriteAll(fd, pixels.data(), pixels.size())) ::_exit(0);
  }
}

// GDCM's codecs (libjpeg, CharLS, OpenJPEG and its RLE decoder, as Debian builds them,
// assertions on) abort or crash the process on malformed streams (found by fuzz_dicom_xray: a
// JPEG whose precision differs from Bits Stored, a segmentation fault in JPEGCodec::Decode). They
// run in a decoder process, forked at the first compressed image and kept for the next ones (a
// fork per image cost ~2 ms, more under the sanitizers); a decoder that dies makes that image an
// error, not the end of carmba, and the next image starts a new one. One decode at a time (a
// mutex); a decoder caught in a loop is stopped after 5 s + 10 s per 100 MB of pixels.
class Decoder {
 public:
  // Returns "" with *out filled, else why not.
  std::string Decode(const std::string& path,
                     const DecodeRequest& request,
                     std::vector<char>* out) {
    std::lock_guard<std::mutex> lock(mutex_);
    if (pid_ < 0) {
      const std::string why = Start();
      if (!why.empty()) return why;
    }
    DecodeRequest r = request;
    r.path_length = static_cast<uint32_t>(path.size());
    if (!WriteAll(fd_, &r, sizeof(r)) || !WriteAll(fd_, path.data(), path.size())) {
      return Died();
    }
    const double limit_s = 5.0 + 10.0 * static_cast<double>(r.expected) / 1e8;
    const auto deadline = std::chrono::steady_clock::now() +
                          std::chrono::duration_cast<std::chrono::steady_clock::duration>(
                              std::chrono::duration<double>(limit_s));
    bool timed_out = false;
    DecodeResponse resp;
    if (!ReadAll(fd_, &resp, sizeof(resp), &deadline, &timed_out)) {
      return timed_out ? Stop(limit_s) : Died();
    }
    if (!resp.ok) return "GDCM cannot decode the pixel data";
    if (resp.length != r.expected) return Died();
    std::vector<char> pixels(resp.length);
    if (!ReadAll(fd_, pixels.data(), pixels.size(), &deadline, &timed_out)) {
      return timed_out ? Stop(limit_s) : Died();
    }
    *out = std::move(pixels);
    return "";
  }

 private:
  std::string Start() {
    int sv[2];
    if (::socketpair(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0, sv) != 0) {
      return std::string("cannot start the decoder: ") + std::strerror(errno);
    }
    std::fflush(nullptr);
    const pid_t pid = ::fork();
    if (pid < 0) {
      const std::string why = std::string("cannot start the decoder: ") + std::strerror(errno);
      ::close(sv[0]);
      ::close(sv[1]);
      return why;
    }
    if (pid == 0) {
      // A failed assertion or a crash in a codec ends the decoder only, without the handlers
      // the parent may have (a sanitizer's, a fuzzer's). SIGINT and SIGTERM, unless ignored, end
      // it too: the parent's handler (util/temp_paths.h) would remove the parent's temporary
      // paths and kill its children from the decoder.
      for (int sig : {SIGABRT, SIGSEGV, SIGBUS, SIGFPE, SIGILL}) ::signal(sig, SIG_DFL);
      for (int sig : {SIGINT, SIGTERM}) {
        if (::signal(sig, SIG_DFL) == SIG_IGN) ::signal(sig, SIG_IGN);
      }
      ::close(sv[0]);
      const int null_fd = ::open("/dev/null", O_WRONLY);
      if (null_fd >= 0) ::dup2(null_fd, 2);  // GDCM's and the codecs' messages
      DecoderLoop(sv[1]);
    }
    ::close(sv[1]);
    pid_ = pid;
    fd_ = sv[0];
    return "";
  }
  // The decoder ended (a crash, an assertion): why, and a new one next time.
  std::string Died() {
    ::close(fd_);
    fd_ = -1;
    int status = 0;
    pid_t waited;
    do {
      waited = ::waitpid(pid_, &status, 0);
    } while (waited < 0 && errno == EINTR);
    pid_ = -1;
    if (waited > 0 && WIFSIGNALED(status)) {
      return "GDCM's decoder died (signal " + std::to_string(WTERMSIG(status)) + ", " +
             ::strsignal(WTERMSIG(status)) + ")";
    }
    return "GDCM's decoder ended without an answer";
  }
  std::string Stop(double limit_s) {
    ::kill(pid_, SIGKILL);
    Died();
    char b[96];
    std::snprintf(b, sizeof(b), "GDCM's decoder did not finish within %.0f s (stopped)", limit_s);
    return b;
  }

  std::mutex mutex_;
  pid_t pid_ = -1;
  int fd_ = -1;
};

Decoder& TheDecoder() {
  static Decoder* decoder = new Decoder;  // never destroyed: the decoder ends at our exit (EOF)
  return *decoder;
}

}  // namespace

Status ReadDicomImage(const std::string& path,
                      const DicomImageOptions& options,
                      DicomImage* out,
                      DicomImageKind* kind) {
  SilenceGdcm();
  *out = DicomImage();
  *kind = DicomImageKind::kNotDicom;
  {
    auto bytes = ReadFile(path);
    if (!bytes.ok()) return bytes.status();
    bool dicom = false;
    const std::string problem = gdcm_util::CheckDicomFile(*bytes, &dicom);
    if (!dicom) return Status::Ok();
    if (!problem.empty()) return Status::Error(path + ": corrupt DICOM file: " + problem);
  }
  out->reader = std::make_unique<gdcm::Reader>();
  out->reader->SetFileName(path.c_str());
  bool parsed;
  {
    QuietStderr quiet;
    parsed = out->reader->Read();
  }
  if (!parsed) return Status::Error(path + ": corrupt DICOM file (GDCM cannot parse it)");
  const gdcm::DataSet& ds = out->data_set();
  out->transfer_syntax_uid = gdcm_util::GetString(out->header(), 0x0002, 0x0010);
  const gdcm::Tag pixel_tag(0x7fe0, 0x0010);
  if (!ds.FindDataElement(pixel_tag)) {
    *kind = DicomImageKind::kNoPixelData;
    return Status::Ok();
  }
  *kind = DicomImageKind::kImage;
  CARMBA_RETURN_IF_ERROR(ReadPixelModule(ds, path, options, out));
  const size_t bytes_per = static_cast<size_t>(out->bits_allocated / 8);
  const size_t expected =
      static_cast<size_t>(out->rows) * out->columns * out->frames * bytes_per;
  const std::string size_text = std::to_string(out->columns) + " x " +
                                std::to_string(out->rows) + " x " + std::to_string(out->frames) +
                                " frames";
  if (!InRange(static_cast<double>(out->rows) * out->columns, plausible::kImagePixels)) {
    return Status::Error(path + ": " + std::to_string(out->columns) + " x " +
                         std::to_string(out->rows) + " px per frame, expected " +
                         FormatRange(plausible::kImagePixels) +
                         " (util/plausible.h kImagePixels; refused before decoding)");
  }
  if (expected > kMaxPixelBytes) {
    return Status::Error(path + ": " + size_text + " of " + std::to_string(bytes_per) +
                         " bytes need " + std::to_string(expected) +
                         " bytes, more than carmba reads (" + std::to_string(kMaxPixelBytes) +
                         ")");
  }
  const gdcm::DataElement& pixel_element = ds.GetDataElement(pixel_tag);
  if (const gdcm::ByteValue* stored = pixel_element.GetByteValue()) {
    // Uncompressed (GDCM has swapped big-endian words to native order; deflated data sets are
    // refused by the structure check).
    if (stored->GetLength() < expected) {
      return Status::Error(path + ": Pixel Data (7fe0,0010) has " +
                           std::to_string(stored->GetLength()) + " bytes, " + size_text +
                           " (Number of Frames (0028,0008)) need " + std::to_string(expected));
    }
    out->pixels.assign(stored->GetPointer(), stored->GetPointer() + expected);
    return Status::Ok();
  }
  if (!pixel_element.GetSequenceOfFragments()) {
    return Status::Error(path + ": Pixel Data (7fe0,0010) is neither a value nor fragments");
  }
  // Compressed: GDCM's codec for the transfer syntax decodes an image described by the values
  // read above.
  const gdcm::TransferSyntax& ts = out->header().GetDataSetTransferSyntax();
  if (!ts.IsEncapsulated()) {
    return Status::Error(path + ": compressed Pixel Data (7fe0,0010) in transfer syntax " +
                         TransferSyntaxName(out->transfer_syntax_uid) +
                         ", which is not a compressed one");
  }
  // GDCM 3.0 aborts on an assertion (ImageCodec::DecodeByStreams) for 8 bits allocated with
  // fewer stored (found by fuzz_dicom_xray); the structure check refuses these already.
  if (out->bits_allocated == 8 && out->bits_stored != 8) {
    return Status::Error(path + ": Bits Stored (0028,0101) " + std::to_string(out->bits_stored) +
                         " with Bits Allocated 8 in compressed pixel data: GDCM cannot decode "
                         "it, expected Bits Stored 8");
  }
  const auto pi = gdcm::PhotometricInterpretation::GetPIType(out->photometric.c_str());
  if (pi != gdcm::PhotometricInterpretation::MONOCHROME1 &&
      pi != gdcm::PhotometricInterpretation::MONOCHROME2) {
    return Status::Error(path + ": Photometric Interpretation (0028,0004) is '" +
                         out->photometric + "', expected MONOCHROME1 or MONOCHROME2");
  }
  DecodeRequest request;
  request.rows = out->rows;
  request.columns = out->columns;
  request.frames = out->frames;
  request.bits_allocated = out->bits_allocated;
  request.bits_stored = out->bits_stored;
  request.high_bit = out->high_bit;
  request.is_signed = out->is_signed ? 1 : 0;
  request.photometric = static_cast<int32_t>(pi);
  request.transfer_syntax = static_cast<int32_t>(static_cast<gdcm::TransferSyntax::TSType>(ts));
  request.expected = expected;
  const size_t length = ImageFor(request, pixel_element)->GetBufferLength();
  if (length != expected) {
    return Status::Error(path + ": the decoded pixel data would have " + std::to_string(length) +
                         " bytes, expected " + std::to_string(expected) + " (" + size_text + ")");
  }
  const std::string why = TheDecoder().Decode(path, request, &out->pixels);
  if (!why.empty()) {
    return Status::Error(path + ": " + why + " (transfer syntax " +
                         TransferSyntaxName(out->transfer_syntax_uid) + ")");
  }
  return Status::Ok();
}

}  // namespace carmba
