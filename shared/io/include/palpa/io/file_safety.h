// File safety for every reader and writer of palpa and palpad (issue 18, findings 4-8): which
// output targets may be replaced, how input files are opened and bounded, and how input bytes are
// quoted in messages. Non-RT (allocates, makes syscalls); compiled without exceptions so that the
// board builds take it.
#pragma once

#include <cstddef>
#include <cstdint>
#include <expected>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "palpa/io/escape.h"

namespace palpa::io {

/// Why a file was refused: the user named something that cannot be used (a device, FIFO, a file
/// too large, an output that is an input: exit 2), or the system failed (open, read: exit 1).
enum class Fault { kBadInput, kSystem };

/// A refusal: its kind and one sentence naming the path (escaped).
struct FileError {
  Fault fault = Fault::kBadInput;
  std::string message;
};

/// Refuses an output target that palpa must not replace: one that exists and is not a regular file
/// (a device, FIFO, socket or directory; a symbolic link is judged by what it names), or that is the
/// same file (st_dev and st_ino) as one of `inputs`. A target that does not exist is accepted (the
/// writer creates it). Errors are Fault::kBadInput and name the path; an input that cannot be
/// stat'ed is ignored (its reader reports it).
[[nodiscard]] std::expected<void, FileError> CheckOutputTarget(std::string_view path,
                                                               std::span<const std::string> inputs = {});

/// Opens `path` for reading only if it is a regular file: the open is non-blocking (a FIFO never
/// hangs it) and the type is checked with fstat on the open descriptor. `what` names the kind of
/// file in messages ("point file", "config file"). Returns the descriptor (blocking again, close-on-
/// exec; the caller closes it) and its size in bytes through `size`.
[[nodiscard]] std::expected<int, FileError> OpenRegular(std::string_view path, std::string_view what,
                                                        std::uint64_t* size = nullptr);

/// Reads a whole regular file of at most `max_bytes` bytes (OpenRegular's checks first; a larger
/// file is refused before any byte is read, and a file that grows while read is cut off and
/// refused). Errors name the path and the cap.
[[nodiscard]] std::expected<std::vector<std::byte>, FileError> ReadBounded(std::string_view path,
                                                                           std::uint64_t max_bytes,
                                                                           std::string_view what);
/// ReadBounded, as text.
[[nodiscard]] std::expected<std::string, FileError> ReadBoundedText(std::string_view path, std::uint64_t max_bytes,
                                                                    std::string_view what);

/// A regular file read line by line in bounded memory: a 64 KiB buffer plus at most `max_line`
/// bytes of the current line. Lines end at '\n' (which is not part of them); the last line needs
/// no '\n'.
class LineReader {
 public:
  enum class Status { kLine, kEnd, kTooLong, kError };

  /// OpenRegular's checks; `max_line` is the longest line accepted, in bytes.
  [[nodiscard]] static std::expected<LineReader, FileError> Open(std::string_view path, std::size_t max_line,
                                                                 std::string_view what);
  LineReader(LineReader&& other) noexcept;
  LineReader& operator=(LineReader&& other) noexcept;
  LineReader(const LineReader&) = delete;
  LineReader& operator=(const LineReader&) = delete;
  ~LineReader();

  /// The next line into `line` (valid until the next call). kTooLong: the line (number
  /// line_number()) is longer than max_line; kError: a read failed (errno is kept in error()).
  Status Next(std::string_view& line);
  /// 1-based number of the line last returned.
  [[nodiscard]] std::uint64_t line_number() const { return line_number_; }
  /// Bytes consumed so far (through the end of the last line returned).
  [[nodiscard]] std::uint64_t offset() const { return offset_; }
  /// The file's size at open.
  [[nodiscard]] std::uint64_t size() const { return size_; }
  /// errno of a failed read.
  [[nodiscard]] int error() const { return error_; }

 private:
  LineReader(int fd, std::size_t max_line, std::uint64_t size);
  bool Fill();

  int fd_ = -1;
  std::size_t max_line_ = 0;
  std::uint64_t size_ = 0;
  std::vector<char> buffer_;
  std::size_t begin_ = 0, end_ = 0;  // unread bytes are buffer_[begin_, end_)
  std::string line_;
  bool eof_ = false;
  std::uint64_t line_number_ = 0;
  std::uint64_t offset_ = 0;
  int error_ = 0;
};

/// "64 KiB", "1 GiB": a byte count for messages.
[[nodiscard]] std::string FormatBytes(std::uint64_t bytes);

}  // namespace palpa::io
