// Recording files: round trip, index, torn tails at every byte, corrupt bytes named by record.
#include "fusion/clients/recording.h"

#include <google/protobuf/util/message_differencer.h>
#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <fstream>
#include <regex>
#include <string>
#include <vector>

#include "fusion/clients/crc32.h"
#include "fusion/clients/importers.h"

namespace fusion::clients {
namespace {

using google::protobuf::util::MessageDifferencer;

std::string TempPath(const std::string& name) {
  return ::testing::TempDir() + "/" + std::to_string(getpid()) + "_" + name;
}

std::string ReadFile(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}
void WriteFile(const std::string& path, const std::string& bytes) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
}

fusion::v1::RecordedCloud MakeCloud(std::uint64_t i) {
  fusion::v1::RecordedCloud cloud;
  cloud.set_sensor_id(i % 2 ? "sr3000" : "stoc");
  cloud.set_sequence_number(100 + i);
  cloud.mutable_stamp()->set_sec(1000 + static_cast<std::int32_t>(i));
  cloud.mutable_stamp()->set_nanosec(500000000);
  cloud.mutable_t_world_sensor()->set_tx(0.1 * static_cast<double>(i));
  cloud.mutable_t_world_sensor()->set_qw(1.0);
  cloud.set_width(static_cast<std::uint32_t>(i + 1));
  cloud.set_height(1);
  for (std::uint64_t k = 0; k <= i; ++k) {
    AppendPoint(static_cast<float>(k), k % 3 == 0 ? NAN : 0.5f, 1.75f, &cloud);
  }
  cloud.set_beyond_range(std::string(i + 1, '\0'));
  cloud.set_receive_time_unix_ns(static_cast<std::int64_t>(i) * 100000000);
  return cloud;
}

// Writes n clouds; returns the byte offset where each cloud frame ends.
std::vector<std::uint64_t> WriteRecording(const std::string& path, int n, bool close = true,
                                          std::uint64_t* header_end = nullptr) {
  std::unique_ptr<RecordingWriter> writer;
  EXPECT_TRUE(RecordingWriter::Create(path, "test", "unit test", &writer).ok());
  if (header_end != nullptr) *header_end = writer->bytes_written();
  std::vector<std::uint64_t> ends;
  for (int i = 0; i < n; ++i) {
    EXPECT_TRUE(writer->Append(MakeCloud(static_cast<std::uint64_t>(i))).ok());
    ends.push_back(writer->bytes_written());
  }
  if (close) {
    EXPECT_TRUE(writer->Close().ok());
  } else {
    // Simulate a crash: no index, no footer. The writer is never closed nor destroyed; kept
    // reachable here so that the leak checker does not report it.
    static std::vector<std::unique_ptr<RecordingWriter>>* const crashed =
        new std::vector<std::unique_ptr<RecordingWriter>>();
    crashed->push_back(std::move(writer));
  }
  return ends;
}

bool SameCloud(const fusion::v1::RecordedCloud& a, const fusion::v1::RecordedCloud& b) {
  // Byte comparison: NaN payloads compare equal as bytes.
  return a.SerializeAsString() == b.SerializeAsString();
}

TEST(Crc32Test, KnownValue) {
  EXPECT_EQ(Crc32("123456789", 9), 0xCBF43926u);
  EXPECT_EQ(Crc32("", 0), 0u);
  EXPECT_EQ(Crc32("56789", 5, Crc32("1234", 4)), 0xCBF43926u);
}

TEST(RecordingTest, RoundTripThroughIndex) {
  const std::string path = TempPath("round_trip.frec");
  WriteRecording(path, 7);
  std::unique_ptr<RecordingReader> reader;
  const Status open = RecordingReader::Open(path, &reader);
  ASSERT_TRUE(open.ok()) << open.message();
  EXPECT_TRUE(reader->indexed()) << reader->index_note();
  EXPECT_TRUE(reader->tail_error().ok());
  EXPECT_EQ(reader->header().magic(), kRecordingMagic);
  EXPECT_EQ(reader->header().writer(), "test");
  ASSERT_EQ(reader->size(), 7u);
  for (std::size_t i = 0; i < 7; ++i) {
    fusion::v1::RecordedCloud cloud;
    const Status s = reader->Read(i, &cloud);
    ASSERT_TRUE(s.ok()) << s.message();
    EXPECT_TRUE(SameCloud(cloud, MakeCloud(i))) << "record " << i;
    EXPECT_EQ(reader->entry(i).sequence_number(), 100 + i);
    EXPECT_EQ(reader->entry(i).stamp().sec(), 1000 + static_cast<int>(i));
  }
  fusion::v1::RecordedCloud cloud;
  EXPECT_FALSE(reader->Read(7, &cloud).ok());
  std::remove(path.c_str());
}

TEST(RecordingTest, EmptyRecordingIsValid) {
  const std::string path = TempPath("empty.frec");
  WriteRecording(path, 0);
  std::unique_ptr<RecordingReader> reader;
  ASSERT_TRUE(RecordingReader::Open(path, &reader).ok());
  EXPECT_TRUE(reader->indexed());
  EXPECT_EQ(reader->size(), 0u);
  std::remove(path.c_str());
}

TEST(RecordingTest, CrashedWriterLeavesScannableRecords) {
  const std::string path = TempPath("crashed.frec");
  WriteRecording(path, 4, /*close=*/false);
  std::unique_ptr<RecordingReader> reader;
  ASSERT_TRUE(RecordingReader::Open(path, &reader).ok());
  EXPECT_FALSE(reader->indexed());
  EXPECT_NE(reader->index_note().find("footer"), std::string::npos) << reader->index_note();
  EXPECT_TRUE(reader->tail_error().ok()) << reader->tail_error().message();
  ASSERT_EQ(reader->size(), 4u);
  fusion::v1::RecordedCloud cloud;
  ASSERT_TRUE(reader->Read(3, &cloud).ok());
  EXPECT_TRUE(SameCloud(cloud, MakeCloud(3)));
  std::remove(path.c_str());
}

// Truncating at every byte keeps every record that ends before the cut, and says where the
// torn record starts.
TEST(RecordingTest, TruncationAtEveryByteKeepsCompleteRecords) {
  const std::string path = TempPath("full.frec");
  std::uint64_t header_end = 0;
  const std::vector<std::uint64_t> ends = WriteRecording(path, 5, true, &header_end);
  const std::string bytes = ReadFile(path);
  const std::string cut_path = TempPath("cut.frec");
  for (std::size_t cut = 0; cut < bytes.size(); ++cut) {
    WriteFile(cut_path, bytes.substr(0, cut));
    std::unique_ptr<RecordingReader> reader;
    const Status open = RecordingReader::Open(cut_path, &reader);
    std::size_t complete = 0;
    while (complete < ends.size() && ends[complete] <= cut) ++complete;
    if (!open.ok()) {
      // Only a torn header makes the file unreadable as a whole.
      ASSERT_LT(cut, header_end) << "cut " << cut << ": " << open.message();
      continue;
    }
    ASSERT_GE(cut, header_end);
    ASSERT_FALSE(reader->indexed()) << "cut " << cut;
    ASSERT_EQ(reader->size(), complete) << "cut " << cut << ": " << reader->tail_error().message();
    for (std::size_t i = 0; i < complete; ++i) {
      fusion::v1::RecordedCloud cloud;
      const Status s = reader->Read(i, &cloud);
      ASSERT_TRUE(s.ok()) << "cut " << cut << ": " << s.message();
      ASSERT_TRUE(SameCloud(cloud, MakeCloud(i))) << "cut " << cut << " record " << i;
    }
    const std::uint64_t torn_start = complete ? ends[complete - 1] : header_end;
    const bool at_boundary = cut == torn_start;
    if (cut < ends.back() && !at_boundary) {
      const std::string expected =
          "record " + std::to_string(complete) + " at byte " + std::to_string(torn_start);
      ASSERT_FALSE(reader->tail_error().ok()) << "cut " << cut;
      ASSERT_NE(reader->tail_error().message().find(expected), std::string::npos)
          << "cut " << cut << ": " << reader->tail_error().message();
      ASSERT_NE(reader->tail_error().message().find("truncated"), std::string::npos);
    }
  }
  std::remove(path.c_str());
  std::remove(cut_path.c_str());
}

TEST(RecordingTest, FlippedByteIsACrcErrorNamingTheRecord) {
  const std::string path = TempPath("flip.frec");
  const std::vector<std::uint64_t> ends = WriteRecording(path, 5);
  std::string bytes = ReadFile(path);
  // A payload byte in the middle of record 2 (which starts where record 1 ends).
  const std::uint64_t start = ends[1];
  bytes[start + kFrameHeaderBytes + 5] ^= 0x40;
  WriteFile(path, bytes);

  std::unique_ptr<RecordingReader> reader;
  ASSERT_TRUE(RecordingReader::Open(path, &reader).ok());
  ASSERT_TRUE(reader->indexed());  // the index is intact; the record itself is not
  fusion::v1::RecordedCloud cloud;
  EXPECT_TRUE(reader->Read(1, &cloud).ok());
  const Status broken = reader->Read(2, &cloud);
  ASSERT_FALSE(broken.ok());
  EXPECT_EQ(
      broken.message().rfind("record 2 at byte " + std::to_string(start) + ": crc mismatch", 0), 0u)
      << broken.message();
  EXPECT_TRUE(reader->Read(3, &cloud).ok());

  // Without the index (footer gone), the scan stops at the same record with the same words.
  WriteFile(path, bytes.substr(0, bytes.size() - kFooterBytes));
  ASSERT_TRUE(RecordingReader::Open(path, &reader).ok());
  EXPECT_FALSE(reader->indexed());
  EXPECT_EQ(reader->size(), 2u);
  EXPECT_EQ(reader->tail_error().message().rfind(
                "record 2 at byte " + std::to_string(start) + ": crc mismatch", 0),
            0u)
      << reader->tail_error().message();
  std::remove(path.c_str());
}

TEST(RecordingTest, CorruptLengthFieldIsNamed) {
  const std::string path = TempPath("length.frec");
  const std::vector<std::uint64_t> ends = WriteRecording(path, 3, /*close=*/false);
  std::string bytes = ReadFile(path);
  bytes[ends[0] + 3] = static_cast<char>(0x7f);  // record 1's length becomes huge
  WriteFile(path, bytes);
  std::unique_ptr<RecordingReader> reader;
  ASSERT_TRUE(RecordingReader::Open(path, &reader).ok());
  EXPECT_EQ(reader->size(), 1u);
  EXPECT_NE(reader->tail_error().message().find("record 1 at byte " + std::to_string(ends[0])),
            std::string::npos)
      << reader->tail_error().message();
  std::remove(path.c_str());
}

TEST(RecordingTest, RejectsOtherFiles) {
  const std::string path = TempPath("not_a_recording.txt");
  WriteFile(path, "hello world, this is not a recording at all\n");
  std::unique_ptr<RecordingReader> reader;
  const Status s = RecordingReader::Open(path, &reader);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("not"), std::string::npos) << s.message();
  EXPECT_FALSE(RecordingReader::Open(TempPath("missing.frec"), &reader).ok());
  std::remove(path.c_str());
}

}  // namespace
}  // namespace fusion::clients
